//! Kernel micro-benchmarks on the formation graph.
//!
//! - `steady_tick`: a robot walking in formation, nothing changes: the cost
//!   Algorithm 1 pays every control tick just to monitor every behavior on
//!   the stack. Goal ≤ 500 ns.
//! - `percept_tick`: the walked distance changes every tick (as it does
//!   while walking), so every termination condition on the stack is
//!   re-evaluated.
//! - `decision_step`: the tick on which a leg ends: pop the stack,
//!   terminate, choose the next behavior, allocate the roles of the next
//!   leg and expand down to the new leaf (silent protocols, one robot).
//! - `heartbeat_at_leader`, `heartbeat_at_member`: a teammate's heartbeat
//!   that changes nothing (its position is the same as the last one).
//! - `condition_eval`: one typical termination condition.

use bite_core::graph::load_str;
use bite_core::ids::{BeliefId, RobotId};
use bite_core::interaction::Registry;
use bite_core::kernel::Kernel;
use bite_core::mission::Mission;
use bite_core::time::Time;
use bite_core::value::Value;
use bite_core::{BehaviorGraph, Config};
use std::sync::Arc;

// The allocator the `bite` binary runs with, so that the figures are its.
#[global_allocator]
static ALLOC: bite_alloc::MiMalloc = bite_alloc::MiMalloc;

fn main() {
    divan::main();
}

fn formation() -> Arc<Mission> {
    let g: BehaviorGraph = load_str(
        &Arc::from("formation.yaml"),
        include_str!("../../../examples/formation.yaml"),
    )
    .expect("formation graph");
    // Silent protocols everywhere, so that one kernel runs alone.
    let cfg = Config::load_str(
        &Arc::from("silent.yaml"),
        "defaults: { terminate: term.local }\nbindings: { formation.terminate: term.local }",
    )
    .expect("config");
    let g = g.with_config(&cfg).expect("config applies");
    Arc::new(Mission::new(g, &Registry::core()).expect("mission"))
}

struct Walking {
    kernel: Kernel,
    leg: BeliefId,
    dist: BeliefId,
    now: Time,
}

/// A kernel of a 3-robot team, robot 0, walking a triangle leg as the lead.
fn walking() -> Walking {
    let m = formation();
    let sym = m.graph().symbols().clone();
    let id = |n: &str| sym.get(n).expect("belief");
    let mut k = Kernel::new(m, RobotId(0), 1);
    let peers = id("peers_located");
    k.tick(Time::ZERO, &[]);
    k.tick(Time::from_millis(100), &[(peers, Value::Bool(true))]);
    k.tick(Time::from_millis(200), &[]);
    while k.poll_output().is_some() {}
    let names: Vec<&str> = k
        .stack()
        .iter()
        .map(|f| k.mission().graph().name_of(f.behavior))
        .collect();
    assert_eq!(names, ["formation", "triangle", "walk", "lead"], "setup");
    Walking {
        leg: id("leg_walked"),
        dist: id("distance_walked"),
        kernel: k,
        now: Time::from_millis(200),
    }
}

#[divan::bench]
fn steady_tick(b: divan::Bencher) {
    let mut w = walking();
    b.bench_local(|| {
        w.now += std::time::Duration::from_millis(100);
        w.kernel.tick(w.now, &[]);
        divan::black_box(w.kernel.poll_output());
    });
}

#[divan::bench]
fn percept_tick(b: divan::Bencher) {
    let mut w = walking();
    let mut d = 0.0;
    b.bench_local(|| {
        w.now += std::time::Duration::from_millis(100);
        d += 1e-6;
        let p = [(w.dist, Value::Num(d)), (w.leg, Value::Num(d))];
        w.kernel.tick(w.now, &p);
        divan::black_box(w.kernel.poll_output());
    });
}

/// One decision step: the end of a leg through to the next leg's leaf.
fn decide(w: &mut Walking) {
    // The leg is over: walk ends, the team chooses `search` (point B), and
    // the robot starts searching; then the search ends, the team chooses
    // `walk` (point A), allocates the roles (point C) and expands to `lead`.
    let peers = w
        .kernel
        .beliefs()
        .symbols()
        .get("peers_located")
        .expect("belief");
    w.kernel.tick(
        w.now,
        &[(w.leg, Value::Num(2.0)), (peers, Value::Bool(false))],
    );
    w.kernel.tick(
        w.now + std::time::Duration::from_millis(100),
        &[(peers, Value::Bool(true)), (w.leg, Value::Num(0.0))],
    );
    while w.kernel.poll_output().is_some() {}
}

#[divan::bench]
fn decision_step(b: divan::Bencher) {
    // Check once, outside the measurement, that the step does what it says.
    let mut w = walking();
    w.now += std::time::Duration::from_millis(100);
    decide(&mut w);
    let g = w.kernel.mission().graph().clone();
    let stack: Vec<(&str, u32)> = w
        .kernel
        .stack()
        .iter()
        .map(|f| (g.name_of(f.behavior), f.epoch))
        .collect();
    assert_eq!(
        stack,
        [("formation", 1), ("triangle", 1), ("walk", 2), ("lead", 1)]
    );
    b.with_inputs(|| {
        let mut w = walking();
        w.now += std::time::Duration::from_millis(100);
        w
    })
    .bench_local_values(|mut w| {
        decide(&mut w);
        divan::black_box(w.kernel.leaf().map(|f| f.behavior));
        w
    });
}

/// The same decision step over and over on one kernel (each step ends where
/// the next begins: walking a leg as the lead), without the setup that
/// `decision_step` pays outside its measurement: the figure to profile.
#[divan::bench]
fn decision_cycle(b: divan::Bencher) {
    let mut w = walking();
    b.bench_local(|| {
        w.now += std::time::Duration::from_millis(200);
        decide(&mut w);
        divan::black_box(w.kernel.leaf().map(|f| f.behavior));
    });
    let g = w.kernel.mission().graph().clone();
    let names: Vec<&str> = w
        .kernel
        .stack()
        .iter()
        .map(|f| g.name_of(f.behavior))
        .collect();
    assert_eq!(
        names,
        ["formation", "triangle", "walk", "lead"],
        "each cycle ends walking"
    );
}

/// Robot `me` of the 3-robot team after the same ticks as [`walking`].
fn walking_robot(me: u32) -> Kernel {
    let m = formation();
    let peers = m.graph().symbols().get("peers_located").expect("belief");
    let mut k = Kernel::new(m, RobotId(me), u64::from(me) + 1);
    k.tick(Time::ZERO, &[]);
    k.tick(Time::from_millis(100), &[(peers, Value::Bool(true))]);
    k.tick(Time::from_millis(200), &[]);
    while k.poll_output().is_some() {}
    k
}

/// A heartbeat that changes nothing: robot `to` hears robot `from`'s
/// position (the same every time: both keep walking), 250 ms apart (the
/// heartbeat period). A team leader hears one from every member four
/// times a second: at 100,000 robots this is most of a run's time.
fn heartbeat(b: divan::Bencher, to: u32, from: u32) {
    let mut k = walking_robot(to);
    let pos = walking_robot(from).position();
    let mut now = Time::from_millis(200);
    b.bench_local(|| {
        now += std::time::Duration::from_millis(250);
        k.peer(now, RobotId(from), divan::black_box(&pos));
        divan::black_box(k.poll_output());
    });
    assert_eq!(
        k.stack().len(),
        4,
        "still walking: the heartbeats changed nothing"
    );
}

/// The leader (robot 0) hears a member's unchanged heartbeat.
#[divan::bench]
fn heartbeat_at_leader(b: divan::Bencher) {
    heartbeat(b, 0, 1);
}

/// A member hears the leader's unchanged heartbeat.
#[divan::bench]
fn heartbeat_at_member(b: divan::Bencher) {
    heartbeat(b, 1, 0);
}

/// Conditions of increasing complexity, on beliefs that are all set.
#[divan::bench(args = [
    "distance_walked >= 6 && peers_located",
    "not obstacle_near",
    "dist(pos, goal) < 0.5 || elapsed > 30 && runs < 3",
    "known(target) && norm(target - pos) * 2 <= max(range, 1) && colour == 'red'",
])]
fn condition(b: divan::Bencher, src: &str) {
    use bite_core::belief::{BeliefStore, Source, Symbols};
    use bite_core::cond::{Expr, Resolver};
    struct R<'a>(&'a mut Symbols);
    impl Resolver for R<'_> {
        fn belief(&mut self, name: &str) -> BeliefId {
            self.0.intern(name)
        }
        fn behavior(&self, _: &str) -> Option<bite_core::ids::BehaviorId> {
            None
        }
    }
    let mut sym = Symbols::new();
    let e = Expr::parse(src, &mut R(&mut sym)).expect("condition parses");
    let sym = Arc::new(sym);
    let mut store = BeliefStore::new(sym.clone());
    let t = Time::ZERO;
    for (name, v) in [
        ("distance_walked", Value::Num(7.0)),
        ("peers_located", Value::Bool(true)),
        ("obstacle_near", Value::Bool(false)),
        ("pos", Value::Vec2([1.0, 2.0])),
        ("goal", Value::Vec2([4.0, 6.0])),
        ("target", Value::Vec2([3.0, 3.0])),
        ("range", Value::Num(5.0)),
        ("colour", Value::from("red")),
    ] {
        store.set_named(name, v, t, Source::Given);
    }
    let runs = bite_core::belief::RunCounts::new();
    let env = bite_core::belief::BeliefEnv {
        beliefs: &store,
        runs: &runs,
        now: Time::from_millis(12_000),
        started: Time::ZERO,
        own: bite_core::ids::BehaviorId(0),
    };
    b.bench_local(|| divan::black_box(e.eval(divan::black_box(&env))));
}

#[divan::bench]
fn condition_eval(b: divan::Bencher) {
    let m = formation();
    let g = m.graph();
    let walk = g.find("formation").expect("formation");
    let until = g.behavior(walk).until.clone().expect("until");
    let w = walking();
    let runs = bite_core::belief::RunCounts::new();
    let env = bite_core::belief::BeliefEnv {
        beliefs: w.kernel.beliefs(),
        runs: &runs,
        now: Time::ZERO,
        started: Time::ZERO,
        own: walk,
    };
    b.bench_local(|| divan::black_box(until.eval(&env)));
}
