//! The fault matrix as a plan of runs: graphs × configurations × worlds ×
//! fault classes × seeds (`bite sweep`; `../shared/RELIABILITY.md`).
//!
//! Every run is independent and a pure function of its [`RunSpec`]: the
//! faults of a run are drawn from its class and seed, and written as
//! [`Fault`] specs, so that `bite run ... --fault SPEC --seed N` replays it
//! exactly. The invariant checker runs on every run; a panic in a run is
//! caught and counted, never taken for a result.

use crate::fault::{Fault, apply_all};
use crate::runner::{RunOptions, derive_seed, run};
use crate::summary::Outcome;
use bite_agent::scenario::Scenario;
use bite_core::interaction::Rng;
use bite_core::mission::Mission;
use rand::{RngExt, SeedableRng};
use serde::Serialize;
use std::sync::Arc;
use std::time::Duration;

/// A fault class of the matrix.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Class {
    /// No fault: the baseline.
    None,
    /// Uniform message loss, 1 % to 30 % (N1).
    Loss,
    /// Heavy loss, 50 % (N2).
    HeavyLoss,
    /// Duplication, 5 % or 30 % of messages delivered 2–3 times (N4).
    Duplication,
    /// Delay and jitter, 50 ms to 2 s (N3, N5: reordering).
    Jitter,
    /// Symmetric partition: the leader isolated, or a random split, for
    /// 1–30 s, then healed (N6).
    Partition,
    /// One-way partition (N7).
    OneWay,
    /// Messages held and released as a burst (N8).
    Hold,
    /// A robot paused 1–10 s, state kept (F5).
    Pause,
    /// A robot crashes for good (F1).
    Crash,
    /// The leader (lowest id) crashes for good (F2).
    LeaderCrash,
    /// A robot's process restarts with a fresh mind (F3, X4).
    Restart,
    /// Clocks skewed ±10 % or ±50 %, offsets up to 5 s (F4).
    ClockSkew,
    /// Forged, replayed and malformed messages (B3–B5, X3, X5).
    Injection,
}

impl Class {
    /// Every class, in table order.
    pub const ALL: [Class; 14] = [
        Class::None,
        Class::Loss,
        Class::HeavyLoss,
        Class::Duplication,
        Class::Jitter,
        Class::Partition,
        Class::OneWay,
        Class::Hold,
        Class::Pause,
        Class::Crash,
        Class::LeaderCrash,
        Class::Restart,
        Class::ClockSkew,
        Class::Injection,
    ];

    /// The name used on the command line and in tables.
    pub fn name(self) -> &'static str {
        match self {
            Class::None => "none",
            Class::Loss => "loss",
            Class::HeavyLoss => "heavy-loss",
            Class::Duplication => "duplication",
            Class::Jitter => "jitter",
            Class::Partition => "partition",
            Class::OneWay => "one-way",
            Class::Hold => "hold",
            Class::Pause => "pause",
            Class::Crash => "crash",
            Class::LeaderCrash => "leader-crash",
            Class::Restart => "restart",
            Class::ClockSkew => "clock-skew",
            Class::Injection => "injection",
        }
    }

    /// The class called `name`.
    pub fn parse(name: &str) -> Option<Class> {
        Class::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The faults of a run of this class: drawn from `seed`, for a team
    /// called `robots` (roster order; the first is the leader).
    pub fn faults(self, seed: u64, robots: &[String]) -> Vec<Fault> {
        let mut rng = Rng::seed_from_u64(derive_seed(seed, self.name(), robots.len() as u32));
        let n = robots.len();
        let secs = |rng: &mut Rng, lo: f64, hi: f64| {
            Duration::from_millis((rng.random_range(lo..=hi) * 1000.0).round() as u64)
        };
        let pick = |rng: &mut Rng| robots[rng.random_range(0..n)].clone();
        match self {
            Class::None => Vec::new(),
            Class::Loss => {
                let p = [0.01, 0.05, 0.1, 0.2, 0.3][rng.random_range(0..5)];
                vec![Fault::Loss(p)]
            }
            Class::HeavyLoss => vec![Fault::Loss(0.5)],
            Class::Duplication => {
                let p = [0.05, 0.3][rng.random_range(0..2)];
                vec![Fault::Dup(p)]
            }
            Class::Jitter => {
                let j = [50, 200, 500, 2000][rng.random_range(0..4)];
                vec![Fault::Jitter(Duration::from_millis(j))]
            }
            Class::Partition if n >= 2 => {
                let at = secs(&mut rng, 2.0, 40.0);
                let len = secs(&mut rng, 1.0, 30.0);
                let groups = if rng.random_bool(0.5) {
                    // The leader alone.
                    vec![vec![robots[0].clone()], robots[1..].to_vec()]
                } else {
                    let mut a = Vec::new();
                    let mut b = Vec::new();
                    for r in robots {
                        if rng.random_bool(0.5) {
                            a.push(r.clone());
                        } else {
                            b.push(r.clone());
                        }
                    }
                    if a.is_empty() {
                        a.push(b.remove(0));
                    }
                    if b.is_empty() {
                        b.push(a.remove(0));
                    }
                    vec![a, b]
                };
                vec![Fault::Partition(groups, at, len)]
            }
            Class::OneWay if n >= 2 => {
                let from = pick(&mut rng);
                let to: Vec<String> = robots.iter().filter(|r| **r != from).cloned().collect();
                let at = secs(&mut rng, 2.0, 40.0);
                let len = secs(&mut rng, 1.0, 30.0);
                vec![Fault::OneWay(vec![from], to, at, len)]
            }
            Class::Hold => vec![Fault::Hold(
                secs(&mut rng, 2.0, 40.0),
                secs(&mut rng, 0.5, 5.0),
            )],
            Class::Pause => vec![Fault::Pause(
                pick(&mut rng),
                secs(&mut rng, 2.0, 40.0),
                secs(&mut rng, 1.0, 10.0),
            )],
            Class::Crash => vec![Fault::Crash(pick(&mut rng), secs(&mut rng, 2.0, 60.0))],
            Class::LeaderCrash => vec![Fault::Crash(robots[0].clone(), secs(&mut rng, 2.0, 60.0))],
            Class::Restart => vec![Fault::Restart(
                pick(&mut rng),
                secs(&mut rng, 2.0, 50.0),
                secs(&mut rng, 0.5, 5.0),
            )],
            Class::ClockSkew => {
                let k = rng.random_range(1..=n.min(2));
                (0..k)
                    .map(|_| {
                        let spread = [0.1, 0.5][rng.random_range(0..2)];
                        let rate: f64 = 1.0 + rng.random_range(-spread..=spread);
                        let off: f64 = rng.random_range(-5.0..=5.0);
                        Fault::Skew(
                            pick(&mut rng),
                            (rate * 1000.0).round() / 1000.0,
                            (off * 1000.0).round() / 1000.0,
                        )
                    })
                    .collect()
            }
            Class::Injection => {
                let every = [20, 100, 500][rng.random_range(0..3)];
                vec![Fault::Inject(Duration::from_millis(every))]
            }
            // A team of one has no network to cut.
            Class::Partition | Class::OneWay => Vec::new(),
        }
    }
}

/// One mission the sweep runs: a graph under a configuration in a world.
#[derive(Clone)]
pub struct Case {
    /// How it is named in tables and replay commands: the arguments of
    /// `bite run` that load it (graph, `--config`, `--scenario` or
    /// `--timed`).
    pub args: String,
    /// The mission.
    pub mission: Arc<Mission>,
    /// The scenario, before faults.
    pub scenario: Scenario,
    /// New versions of the mission handed to the team as it runs (the
    /// scenario's `mission_changes:`, loaded).
    pub changes: Vec<crate::runner::Change>,
}

/// One run of the sweep.
#[derive(Clone, Debug)]
pub struct RunSpec {
    /// Which case.
    pub case: usize,
    /// Which fault class.
    pub class: Class,
    /// The seed (of the run and of its faults).
    pub seed: u64,
}

/// What one run gave.
#[derive(Clone, Debug, Serialize)]
pub struct RunResult {
    /// The case's `bite run` arguments.
    pub case: String,
    /// The fault class.
    pub class: Class,
    /// The seed.
    pub seed: u64,
    /// The faults, as specs.
    pub faults: Vec<String>,
    /// How it ended (`None`: it panicked).
    pub outcome: Option<Outcome>,
    /// Simulated task time, seconds.
    pub task_time: f64,
    /// Protocol instances that needed their deadline.
    pub timeouts: u64,
    /// Protocol messages sent (a team multicast counts once): a run whose
    /// robots answer each other in a loop stands out here.
    pub messages: u64,
    /// Invariant violations.
    pub violations: usize,
    /// A robot sent kernel messages far faster than any protocol needs
    /// (see [`crate::chatter`]): a failure, though no invariant broke.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub chatter: bool,
    /// The first violation, the stall, the chatter, or the panic message.
    pub detail: Option<String>,
    /// True when the run panicked.
    pub panicked: bool,
    /// The command that replays it.
    pub replay: String,
    /// The run's whole summary (`None`: it panicked). Not written to the
    /// sweep's log, which keeps one short line per run.
    #[serde(skip)]
    pub summary: Option<Box<crate::summary::Summary>>,
}

impl RunResult {
    /// True when the run broke something: an invariant, or a panic, or a
    /// robot chattered.
    pub fn failed(&self) -> bool {
        self.panicked || self.violations > 0 || self.chatter
    }
}

/// Every run of the plan, in a fixed order (cases, then classes, then
/// seeds), so that results come out the same whatever runs them.
pub fn plan(cases: usize, classes: &[Class], seeds: &[u64]) -> Vec<RunSpec> {
    let mut out = Vec::with_capacity(cases * classes.len() * seeds.len());
    for case in 0..cases {
        for class in classes {
            for seed in seeds {
                out.push(RunSpec {
                    case,
                    class: *class,
                    seed: *seed,
                });
            }
        }
    }
    out
}

/// Run one run of the plan.
pub fn run_one(cases: &[Case], spec: &RunSpec) -> RunResult {
    let case = &cases[spec.case];
    let robots: Vec<String> = (0..case.mission.graph().roster().len() as u32)
        .map(|r| {
            case.mission
                .graph()
                .roster()
                .name(bite_core::ids::RobotId(r))
        })
        .collect();
    let faults = spec.class.faults(spec.seed, &robots);
    let specs: Vec<String> = faults.iter().map(ToString::to_string).collect();
    let replay = format!(
        "bite run {}{} --seed {}",
        case.args,
        specs
            .iter()
            .map(|f| format!(" --fault '{f}'"))
            .collect::<String>(),
        spec.seed
    );
    let scenario = apply_all(&case.scenario, &faults);
    let mission = case.mission.clone();
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        run(
            mission,
            &scenario,
            RunOptions {
                seed: Some(spec.seed),
                changes: case.changes.clone(),
                ..RunOptions::default()
            },
        )
    }));
    let mut r = RunResult {
        case: case.args.clone(),
        class: spec.class,
        seed: spec.seed,
        faults: specs,
        outcome: None,
        task_time: 0.0,
        timeouts: 0,
        messages: 0,
        violations: 0,
        chatter: false,
        detail: None,
        panicked: false,
        replay,
        summary: None,
    };
    match outcome {
        Ok(Ok(report)) => {
            let s = &report.summary;
            r.outcome = Some(s.outcome);
            r.task_time = s.task_time;
            r.timeouts = s.timeouts;
            r.messages = s.messages.total();
            r.violations = report.violations.len();
            r.chatter = s.chatter.is_some();
            r.detail = report
                .violations
                .first()
                .map(ToString::to_string)
                .or_else(|| s.stall.clone())
                .or_else(|| s.chatter.clone());
            r.summary = Some(Box::new(report.summary));
        }
        Ok(Err(d)) => {
            r.detail = Some(d.to_string());
            r.panicked = true;
        }
        Err(p) => {
            r.panicked = true;
            r.detail = Some(
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "panic".to_string()),
            );
        }
    }
    r
}

/// The totals of one fault class.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ClassTotals {
    /// The class.
    pub class: String,
    /// Runs.
    pub runs: usize,
    /// Completed without a deadline.
    pub completed: usize,
    /// Completed, with some instance at its deadline.
    pub completed_with_timeouts: usize,
    /// Stalled.
    pub stalled: usize,
    /// Not completed by the time limit.
    pub not_completed: usize,
    /// Runs that broke an invariant.
    pub violations: usize,
    /// Runs that panicked.
    pub panics: usize,
}

impl ClassTotals {
    /// Share of runs that completed (with or without timeouts).
    pub fn completion(&self) -> f64 {
        (self.completed + self.completed_with_timeouts) as f64 / self.runs.max(1) as f64
    }
}

/// Totals per class, in the order of `classes`.
pub fn totals(classes: &[Class], results: &[RunResult]) -> Vec<ClassTotals> {
    classes
        .iter()
        .map(|c| {
            let mut t = ClassTotals {
                class: c.name().to_string(),
                ..ClassTotals::default()
            };
            for r in results.iter().filter(|r| r.class == *c) {
                t.runs += 1;
                match r.outcome {
                    Some(Outcome::Completed) => t.completed += 1,
                    Some(Outcome::CompletedWithTimeouts) => t.completed_with_timeouts += 1,
                    Some(Outcome::Stalled) => t.stalled += 1,
                    Some(Outcome::NotCompleted) => t.not_completed += 1,
                    None => {}
                }
                t.violations += usize::from(r.violations > 0);
                t.panics += usize::from(r.panicked);
            }
            t
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_class_draws_specs_that_parse_back() {
        let robots: Vec<String> = (0..4).map(|i| format!("r{i}")).collect();
        for c in Class::ALL {
            assert_eq!(Class::parse(c.name()), Some(c));
            for seed in 1..20 {
                let a = c.faults(seed, &robots);
                assert_eq!(
                    a,
                    c.faults(seed, &robots),
                    "{c:?} is a function of its seed"
                );
                for f in &a {
                    assert_eq!(Fault::parse(&f.to_string()).as_ref(), Ok(f), "{f}");
                }
            }
        }
    }
}
