//! Protocol probes: run one coordination point under one protocol, in the
//! discrete-event runner, and measure what a decision costs — messages,
//! bytes, rounds — and what it decided. `bite bench protocols` and the
//! protocol tests are built on it.
//!
//! A probe generates a small mission around the point:
//!
//! - **sync**: every robot runs `a` (a skill that takes exactly 1 s), then
//!   the team chooses among `items` successors at the point under test;
//! - **allocate**: after a 0.5 s warm-up, the team splits among `items`
//!   children at the point under test (each child takes one member or any
//!   number, `one_each`); with `utilities`, robot `i` stands at a random
//!   point `pos` of a 100 m square, child `j` wants a random place `p_j`,
//!   and its utility for a robot is `150 − dist(pos, p_j)` (always
//!   positive);
//! - **terminate**: every robot runs `w` under the point under test; `w`
//!   ends for each robot after exactly 1 s (with `staggered`, one robot
//!   after the other, 0.5 s apart, the leader last).
//!
//! Everything else is bound to the silent rules, so the point under test is
//! the only one that communicates. With a fixed latency and no jitter a
//! round of messages takes exactly one latency: the time from the first
//! robot starting the instance (reaching the point, or finishing its part)
//! to the last robot deciding, divided by the latency, is the number of
//! rounds.

use crate::check::{Violation, check};
use crate::runner::{RunOptions, prepare, run};
use bite_agent::scenario::Scenario;
use bite_core::diag::Diagnostics;
use bite_core::event::{Event, MembersLog, OutcomeLog};
use bite_core::graph::load_str;
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::interaction::{Registry, Rng};
use bite_core::msg::Kind;
use rand::{RngExt, SeedableRng};
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Duration;

/// Every protocol of the library with the parameters a probe gives it, in
/// the order `bite bench protocols` reports them.
pub const LIBRARY: &[(Kind, &str, Option<&str>)] = &[
    (Kind::Sync, "sync.by-rule", None),
    (Kind::Sync, "sync.round-robin", None),
    (Kind::Sync, "sync.leader", None),
    (Kind::Sync, "sync.elected-leader", None),
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

/// The graph-defined protocols of `examples/protocols/` with the
/// parameters a probe gives them (after [`LIBRARY`] in `bite bench
/// protocols`, beside their Rust twins).
pub const GRAPH_LIBRARY: &[(Kind, &str, Option<&str>)] = &[
    (Kind::Sync, "graph.vote", None),
    (Kind::Sync, "graph.quorum-vote", None),
    (Kind::Allocate, "graph.market", Some("{ bid: x }")),
    (Kind::Terminate, "graph.wait-all", None),
];

/// What to measure.
#[derive(Clone, Debug)]
pub struct ProbeSpec {
    /// Kind of the point.
    pub kind: Kind,
    /// Protocol name (or alias).
    pub protocol: String,
    /// Protocol parameters, as a YAML flow mapping (`{ value: x }`).
    pub params: Option<String>,
    /// Team size.
    pub robots: usize,
    /// Successors (sync) or children (allocate); at least 2 for sync.
    pub items: usize,
    /// Allocation: each child takes exactly one member (tasks), instead of
    /// one or more.
    pub one_each: bool,
    /// Allocation: children have utilities (see the module documentation);
    /// synchronization: each robot prefers the successors by seeded
    /// utilities (small integers: robots disagree, votes tie).
    pub utilities: bool,
    /// Termination: robots finish one after the other, 0.5 s apart, the
    /// highest id first and the leader last.
    pub staggered: bool,
    /// One-way network latency (fixed).
    pub latency: Duration,
    /// Extra random delay, uniform in `[0, jitter]` (reorders).
    pub jitter: Duration,
    /// Loss probability.
    pub loss: f64,
    /// Duplication probability.
    pub duplicate: f64,
    /// Retransmission interval of the binding (default: the protocol's).
    pub retry: Option<Duration>,
    /// Deadline of the binding (default: the protocol's).
    pub deadline: Option<Duration>,
    /// Crash this robot at this time (for lost-teammate tests).
    pub crash: Option<(usize, Duration)>,
    /// Seed of the run and of the positions.
    pub seed: u64,
}

impl ProbeSpec {
    /// The probe `bite bench protocols` runs for an entry of [`LIBRARY`]:
    /// [`ProbeSpec::new`] with the parameters, and first-wins with members
    /// finishing one after the other (it is about one robot seeing the goal
    /// before the others).
    pub fn library(kind: Kind, protocol: &str, params: Option<&str>, robots: usize) -> Self {
        let mut s = Self::new(kind, protocol, robots);
        s.params = params.map(str::to_string);
        s.staggered = protocol == "term.first-wins";
        s
    }

    /// A fault-free probe of `protocol` at a point of `kind` with `robots`
    /// robots and 3 items; 10 ms latency.
    pub fn new(kind: Kind, protocol: &str, robots: usize) -> Self {
        ProbeSpec {
            kind,
            protocol: protocol.to_string(),
            params: None,
            robots,
            items: 3,
            one_each: false,
            utilities: false,
            staggered: false,
            latency: Duration::from_millis(10),
            jitter: Duration::ZERO,
            loss: 0.0,
            duplicate: 0.0,
            retry: None,
            deadline: None,
            crash: None,
            seed: 1,
        }
    }
}

/// What a probe measured.
#[derive(Clone, Debug)]
pub struct ProbeResult {
    /// Every robot that did not crash completed the mission.
    pub completed: bool,
    /// Messages sent at the point (a team multicast counts once).
    pub messages: u64,
    /// Bytes sent at the point.
    pub bytes: u64,
    /// Distinct decisions (instances) at the point.
    pub instances: u64,
    /// Longest wait for the decision, seconds.
    pub max_wait: f64,
    /// Message rounds: from the first robot starting the instance to the
    /// last deciding, in latencies.
    pub rounds: f64,
    /// Robots that hit the deadline at the point.
    pub timeouts: u64,
    /// Protocol violations reported by kernels.
    pub protocol_violations: u64,
    /// Invariants broken (see [`crate::check`]).
    pub violations: Vec<Violation>,
    /// The allocation the lowest-id live robot applied (allocation probes).
    pub assignment: Option<Vec<(BehaviorId, Vec<RobotId>)>>,
    /// Its total utility (allocation probes with utilities).
    pub utility: Option<f64>,
    /// The choice the robots applied (sync probes): one per robot.
    pub choices: Vec<Option<BehaviorId>>,
    /// Simulated time of the run, seconds.
    pub sim_time: f64,
}

/// Robot and item positions of a probe with utilities.
pub fn positions(spec: &ProbeSpec) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let mut rng = Rng::seed_from_u64(spec.seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut pt = || [rng.random_range(0.0..100.0), rng.random_range(0.0..100.0)];
    let robots = (0..spec.robots).map(|_| pt()).collect();
    let items = (0..spec.items).map(|_| pt()).collect();
    (robots, items)
}

/// Utility of item `j` for robot `i` in a probe with utilities.
pub fn utility(robot: [f64; 2], item: [f64; 2]) -> f64 {
    150.0 - ((robot[0] - item[0]).powi(2) + (robot[1] - item[1]).powi(2)).sqrt()
}

fn binding(spec: &ProbeSpec) -> String {
    let mut b = format!("{{ protocol: {}", spec.protocol);
    if let Some(r) = spec.retry {
        let _ = write!(b, ", retry: {}ms", r.as_millis().max(1));
    }
    if let Some(d) = spec.deadline {
        let _ = write!(b, ", deadline: {}ms", d.as_millis().max(1));
    }
    if let Some(p) = &spec.params {
        let _ = write!(b, ", params: {p}");
    }
    b.push_str(" }");
    b
}

/// The graph and scenario of a probe, as YAML text.
pub fn mission_text(spec: &ProbeSpec) -> (String, String) {
    let bind = binding(spec);
    let mut g = format!(
        "graph: probe-{}\nteam: {{ robots: {} }}\nstart: root\n\
         defaults: {{ sync: sync.by-rule, allocate: alloc.by-id, terminate: term.local }}\n\
         behaviors:\n",
        spec.protocol, spec.robots
    );
    let mut skills = String::new();
    let mut events = String::new();
    match spec.kind {
        Kind::Sync => {
            let succ: Vec<String> = (0..spec.items.max(2)).map(|i| format!("s{i}")).collect();
            let _ = write!(
                g,
                "  root: {{ team: true, children: [a] }}\n  \
                 a: {{ team: true, skill: work, until: done, next: [{}], sync: {bind} }}\n",
                succ.join(", ")
            );
            for (j, s) in succ.iter().enumerate() {
                let utility = if spec.utilities {
                    format!(", utility: u{j}")
                } else {
                    String::new()
                };
                let _ = writeln!(
                    g,
                    "  {s}: {{ team: true, skill: rest, until: rested{utility} }}"
                );
            }
            if spec.utilities {
                // Each robot's preference: small integers, so that robots
                // disagree and votes tie.
                let mut rng = Rng::seed_from_u64(spec.seed ^ 0x5eed_u64);
                events.push_str("events:\n");
                for i in 0..spec.robots {
                    let set: Vec<String> = (0..succ.len())
                        .map(|j| format!("u{j}: {}", rng.random_range(0..3u32)))
                        .collect();
                    let _ = writeln!(
                        events,
                        "  - {{ at: 0s, robots: [r{i}], set: {{ {} }} }}",
                        set.join(", ")
                    );
                }
            }
            skills.push_str(
                "  work: { duration: 1, start: { done: false }, done: { done: true } }\n  \
                 rest: { duration: 1, start: { rested: false }, done: { rested: true } }\n",
            );
        }
        Kind::Allocate => {
            let kids: Vec<String> = (0..spec.items.max(1)).map(|i| format!("c{i}")).collect();
            let _ = write!(
                g,
                "  root: {{ team: true, children: [warmup] }}\n  \
                 warmup: {{ team: true, skill: prep, until: ready, next: [split] }}\n  \
                 split: {{ team: true, children: [{}], allocate: {bind} }}\n",
                kids.join(", ")
            );
            let (robots, items) = positions(spec);
            let members = if spec.one_each { "\"1\"" } else { "\"1..\"" };
            for (i, k) in kids.iter().enumerate() {
                let _ = write!(
                    g,
                    "  {k}: {{ team: true, skill: task, until: finished, members: {members}"
                );
                if spec.utilities {
                    let p = items[i];
                    let _ = write!(g, ", utility: '150 - dist(pos, [{}, {}])'", p[0], p[1]);
                }
                g.push_str(" }\n");
            }
            skills.push_str(
                "  prep: { duration: 0.5, start: { ready: false }, done: { ready: true } }\n  \
                 task: { duration: 1, start: { finished: false }, done: { finished: true } }\n",
            );
            if spec.utilities {
                events.push_str("events:\n");
                for (i, p) in robots.iter().enumerate() {
                    let _ = writeln!(
                        events,
                        "  - {{ at: 0s, robots: [r{i}], set: {{ pos: [{}, {}] }} }}",
                        p[0], p[1]
                    );
                }
            }
        }
        Kind::Terminate => {
            let _ = write!(
                g,
                "  root: {{ team: true, children: [w] }}\n  \
                 w: {{ team: true, skill: work, until: done, terminate: {bind} }}\n"
            );
            if spec.staggered {
                // Robot n-1 first, robot 0 (the leader) last, 0.5 s apart.
                skills.push_str("  work: { start: { done: false } }\n");
                events.push_str("events:\n");
                for i in 0..spec.robots {
                    let at = 1.0 + 0.5 * (spec.robots - 1 - i) as f64;
                    let _ = writeln!(
                        events,
                        "  - {{ at: {at}s, robots: [r{i}], set: {{ done: true }} }}"
                    );
                }
            } else {
                skills.push_str(
                    "  work: { duration: 1, start: { done: false }, done: { done: true } }\n",
                );
            }
        }
    }
    let mut s = format!(
        "scenario: probe\nworld: timed\nseed: {}\ncontrol_hz: 10\ntime_limit: 36000s\n\
         network: {{ latency: {}us, jitter: {}us, loss: {}, duplicate: {} }}\nskills:\n{skills}{events}",
        spec.seed,
        spec.latency.as_micros(),
        spec.jitter.as_micros(),
        spec.loss,
        spec.duplicate
    );
    if let Some((r, at)) = spec.crash {
        let _ = writeln!(
            s,
            "crashes:\n  - {{ robot: r{r}, at: {}us }}",
            at.as_micros()
        );
    }
    (g, s)
}

/// Run a probe.
pub fn probe(spec: &ProbeSpec, registry: &Registry) -> Result<ProbeResult, Diagnostics> {
    let (g, s) = mission_text(spec);
    let graph = load_str(&Arc::from("probe.yaml"), &g)?;
    let sc = Scenario::load_str(&Arc::from("probe-scenario.yaml"), &s)?;
    let mission = prepare(&graph, &sc, None, registry)?;
    let report = run(
        mission.clone(),
        &sc,
        RunOptions {
            record: true,
            ..RunOptions::default()
        },
    )?;
    let violations = check(&report, &mission);
    let point = match spec.kind {
        Kind::Sync => "a.sync",
        Kind::Allocate => "split.allocate",
        Kind::Terminate => "w.terminate",
    };
    let p = report
        .summary
        .points
        .iter()
        .find(|p| p.point == point)
        .cloned()
        .unwrap_or_default();
    let at = mission.graph().find(match spec.kind {
        Kind::Sync => "a",
        Kind::Allocate => "split",
        Kind::Terminate => "w",
    });
    let crashed = spec.crash.map(|(r, _)| RobotId(r as u32));
    let mut assignment = None;
    let mut choices = Vec::new();
    let (mut first_start, mut last_decision) = (f64::INFINITY, 0.0f64);
    for rec in &report.history {
        match &rec.event {
            Event::InteractionStarted { instance, .. }
                if Some(instance.behavior) == at && instance.kind == spec.kind =>
            {
                first_start = first_start.min(rec.t.as_secs_f64());
            }
            Event::InteractionDecided { instance, .. }
                if Some(instance.behavior) == at && instance.kind == spec.kind =>
            {
                last_decision = last_decision.max(rec.t.as_secs_f64());
            }
            _ => {}
        }
        if let Event::InteractionDecided {
            instance, outcome, ..
        } = &rec.event
            && Some(instance.behavior) == at
            && instance.kind == spec.kind
        {
            match outcome {
                OutcomeLog::Allocate { assignment: a }
                    if Some(rec.robot) != crashed && assignment.is_none() =>
                {
                    assignment = Some(
                        a.iter()
                            .map(|(b, m)| {
                                let list = match m {
                                    MembersLog::List(v) => v.to_vec(),
                                    MembersLog::Summary { .. } => Vec::new(),
                                };
                                (*b, list)
                            })
                            .collect::<Vec<_>>(),
                    );
                }
                OutcomeLog::Sync { choice } => choices.push(*choice),
                _ => {}
            }
        }
    }
    let utility = match (&assignment, spec.utilities) {
        (Some(a), true) => {
            let (robots, items) = positions(spec);
            let g = mission.graph();
            let mut total = 0.0;
            for (b, members) in a {
                let j: usize = g.name_of(*b)[1..].parse().unwrap_or(0);
                for r in members {
                    total += utility(robots[r.index()], items[j]);
                }
            }
            Some(total)
        }
        _ => None,
    };
    let latency = spec.latency.as_secs_f64().max(1e-9);
    Ok(ProbeResult {
        completed: report.summary.completed,
        messages: p.messages,
        bytes: p.bytes,
        instances: p.instances,
        max_wait: p.max_wait,
        rounds: if first_start.is_finite() {
            ((last_decision - first_start).max(0.0) / latency * 100.0).round() / 100.0
        } else {
            0.0
        },
        timeouts: p.timeouts,
        protocol_violations: report.summary.violations,
        violations,
        assignment,
        utility,
        choices,
        sim_time: report.end.as_secs_f64(),
    })
}
