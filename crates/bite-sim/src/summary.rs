//! The summary at the end of a run: did the mission complete, how long it
//! took, how long robots spent in each kind of interaction, and what the
//! coordination cost in messages and bytes — per kind and per point.

use crate::net::NetStats;
use bite_core::event::{DropReason, Event};
use bite_core::ids::{BehaviorId, RobotId};
use bite_core::mission::Mission;
use bite_core::msg::Kind;
use bite_core::time::Time;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

/// A quantity per interaction kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PerKind<T> {
    /// Synchronization.
    pub sync: T,
    /// Allocation.
    pub allocate: T,
    /// Termination.
    pub terminate: T,
}

impl<T: Copy + std::ops::Add<Output = T>> PerKind<T> {
    /// The slot of a kind.
    pub fn get_mut(&mut self, k: Kind) -> &mut T {
        match k {
            Kind::Sync => &mut self.sync,
            Kind::Allocate => &mut self.allocate,
            Kind::Terminate => &mut self.terminate,
        }
    }
    /// The value of a kind.
    pub fn get(&self, k: Kind) -> T {
        match k {
            Kind::Sync => self.sync,
            Kind::Allocate => self.allocate,
            Kind::Terminate => self.terminate,
        }
    }
    /// Sum over kinds.
    pub fn total(&self) -> T {
        self.sync + self.allocate + self.terminate
    }
}

/// Cost of one coordination point over the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PointSummary {
    /// Point name.
    pub point: String,
    /// Kind.
    pub kind: String,
    /// Protocol bound to it.
    pub protocol: String,
    /// Distinct instances decided (team decisions).
    pub instances: u64,
    /// Per-robot decisions (each member decides each instance).
    pub decisions: u64,
    /// Mean time a robot waited for a decision, seconds.
    pub mean_wait: f64,
    /// Longest wait, seconds.
    pub max_wait: f64,
    /// Messages sent (a team multicast counts once).
    pub messages: u64,
    /// Bytes sent.
    pub bytes: u64,
    /// Instances that hit their deadline (per robot).
    pub timeouts: u64,
}

/// How a run ended. Each has its own exit code (`bite run`, `bite
/// robot`, `bite launch`; see the README).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// Every live robot completed the mission, and no protocol instance
    /// needed its deadline.
    Completed,
    /// Every live robot completed, but some protocol instance decided only
    /// at its deadline (a teammate was silent, or something stalled for a
    /// while).
    CompletedWithTimeouts,
    /// The run made no progress for too long, or went round in circles
    /// (see `stall`).
    Stalled,
    /// The time limit came first.
    NotCompleted,
}

impl Outcome {
    /// The outcome as printed in summaries.
    pub fn label(self) -> &'static str {
        match self {
            Outcome::Completed => "COMPLETED",
            Outcome::CompletedWithTimeouts => "COMPLETED WITH TIMEOUTS",
            Outcome::Stalled => "STALLED",
            Outcome::NotCompleted => "NOT COMPLETED",
        }
    }
    /// The exit code of a run that ended so (with no invariant violated).
    pub fn exit_code(self) -> u8 {
        match self {
            Outcome::Completed => 0,
            Outcome::NotCompleted => 1,
            Outcome::CompletedWithTimeouts => 4,
            Outcome::Stalled => 5,
        }
    }
}

/// Exit code of a run that broke an invariant, whatever its outcome.
pub const EXIT_VIOLATION: u8 = 6;

/// The summary of a run.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Graph name.
    pub graph: String,
    /// Configuration name.
    pub config: Option<String>,
    /// Scenario name.
    pub scenario: String,
    /// Seed.
    pub seed: u64,
    /// Team size.
    pub robots: usize,
    /// How the run ended.
    pub outcome: Outcome,
    /// What stalled, when the outcome is `stalled`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stall: Option<String>,
    /// A robot that sent kernel messages far faster than any protocol
    /// needs (see `chatter`), if one did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chatter: Option<String>,
    /// True when every live robot completed the mission (with or without
    /// timeouts).
    pub completed: bool,
    /// Robots that completed.
    pub completed_robots: usize,
    /// Robots that crashed.
    pub crashed_robots: usize,
    /// Task time: when the last live robot completed (or the time limit), seconds.
    pub task_time: f64,
    /// Mean time per live robot spent waiting in interactions, seconds.
    pub interaction_time: PerKind<f64>,
    /// Longest time one robot spent in each kind of interaction, seconds
    /// (per kind, possibly different robots).
    pub interaction_time_max: PerKind<f64>,
    /// Longest total interaction time of one robot, seconds.
    pub interaction_time_max_total: f64,
    /// Per-robot decisions.
    pub decisions: PerKind<u64>,
    /// Per-robot instances that hit their deadline.
    pub timeouts: u64,
    /// Messages sent (multicast counts once).
    pub messages: PerKind<u64>,
    /// Bytes sent.
    pub bytes: PerKind<u64>,
    /// What the network did (heartbeats included).
    pub network: NetStats,
    /// Heartbeats sent (positions for the team view; not coordination
    /// messages).
    pub heartbeats: Heartbeats,
    /// Forged, replayed or malformed messages injected, by kind (scenario
    /// `inject:`).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub injected: BTreeMap<String, u64>,
    /// Messages dropped by kernels, by reason.
    pub dropped: BTreeMap<DropReason, u64>,
    /// Protocol violations reported (a teammate's message broke a
    /// protocol's rules; it was ignored).
    pub violations: u64,
    /// The invariants checked over the run, and what broke.
    pub invariants: crate::check::Invariants,
    /// Per point.
    pub points: Vec<PointSummary>,
    /// Fingerprint of the run log (equal logs have equal fingerprints).
    pub log_fingerprint: String,
    /// The physical world's results (`world: physics`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub world: Option<WorldSummary>,
    /// The world models' messages (when the team shares beliefs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sharing: Option<bite_core::wm::SharingTotals>,
    /// New versions of the mission handed to the team, and which version
    /// each robot ran at the end (runs with mission changes only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub versions: Option<Versions>,
}

/// The versions of a changed mission at the end of a run.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Versions {
    /// New versions handed to the team.
    pub handed: u32,
    /// Live robots by the version they ran at the end.
    pub robots: BTreeMap<u32, usize>,
}

/// Heartbeat copies sent and their bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Heartbeats {
    /// Copies sent (one per recipient).
    pub messages: u64,
    /// Bytes of the positions they carried.
    pub bytes: u64,
}

/// What happened in the physical world.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct WorldSummary {
    /// The scenario's goal (object in zone), if it has one, and when it was met.
    pub goal: Option<String>,
    /// When the goal was met, seconds.
    pub goal_met_at: Option<f64>,
    /// Distance each robot travelled, m.
    pub distance: Vec<f64>,
    /// Share of the arena within 0.5 m of some robot's path (0-1).
    pub coverage: f64,
    /// Formation error, m: mean and largest distance of a slot keeper from
    /// its slot (true poses), if any robot kept a slot.
    pub formation_error: Option<[f64; 2]>,
    /// When some robot's camera first saw each named object, seconds
    /// (objects never seen are left out).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub first_seen: BTreeMap<String, f64>,
}

/// Collects a summary from the event stream.
#[derive(Debug, Default)]
pub struct Aggregator {
    wait: Vec<PerKind<f64>>,
    decisions: PerKind<u64>,
    timeouts: u64,
    messages: PerKind<u64>,
    bytes: PerKind<u64>,
    violations: u64,
    completed: BTreeMap<RobotId, Time>,
    points: BTreeMap<(BehaviorId, Kind), PointAcc>,
}

/// Running totals of one point.
#[derive(Debug, Default)]
struct PointAcc {
    summary: PointSummary,
    /// Instances seen (team, epoch), to count each once.
    seen: BTreeSet<(u64, u32)>,
    total_wait: f64,
}

impl Aggregator {
    /// For a team of `n`.
    pub fn new(n: usize) -> Self {
        Aggregator {
            wait: vec![PerKind::default(); n],
            ..Default::default()
        }
    }

    fn point(&mut self, b: BehaviorId, k: Kind) -> &mut PointAcc {
        self.points.entry((b, k)).or_default()
    }

    /// Account one sent message.
    pub fn sent(&mut self, b: BehaviorId, k: Kind, bytes: u32) {
        *self.messages.get_mut(k) += 1;
        *self.bytes.get_mut(k) += u64::from(bytes);
        let p = &mut self.point(b, k).summary;
        p.messages += 1;
        p.bytes += u64::from(bytes);
    }

    /// Account one event.
    pub fn event(&mut self, t: Time, robot: RobotId, e: &Event) {
        match e {
            Event::InteractionDecided {
                instance,
                waited_us,
                timed_out,
                ..
            } => {
                let w = *waited_us as f64 / 1e6;
                if let Some(slot) = self.wait.get_mut(robot.index()) {
                    *slot.get_mut(instance.kind) += w;
                }
                *self.decisions.get_mut(instance.kind) += 1;
                let acc = self.point(instance.behavior, instance.kind);
                let p = &mut acc.summary;
                p.decisions += 1;
                acc.total_wait += w;
                p.max_wait = p.max_wait.max(w);
                if *timed_out {
                    p.timeouts += 1;
                }
                if acc.seen.insert((instance.team.0, instance.epoch)) {
                    p.instances += 1;
                }
            }
            Event::InteractionTimedOut { .. } => self.timeouts += 1,
            Event::ProtocolViolation { .. } => self.violations += 1,
            Event::MissionCompleted => {
                self.completed.insert(robot, t);
            }
            _ => {}
        }
    }

    /// Time when `robot` completed, if it did.
    pub fn completed_at(&self, robot: RobotId) -> Option<Time> {
        self.completed.get(&robot).copied()
    }

    /// Finish the summary.
    #[allow(clippy::too_many_arguments)]
    pub fn finish(
        self,
        mission: &Mission,
        scenario: &str,
        seed: u64,
        end: Time,
        crashed: &[bool],
        network: NetStats,
        dropped: BTreeMap<DropReason, u64>,
        log_fingerprint: u64,
    ) -> Summary {
        let graph = mission.graph();
        let n = crashed.len();
        let live: Vec<RobotId> = (0..n as u32)
            .map(RobotId)
            .filter(|r| !crashed[r.index()])
            .collect();
        let completed_robots = live
            .iter()
            .filter(|r| self.completed.contains_key(r))
            .count();
        let completed = !live.is_empty() && completed_robots == live.len();
        let task_time = if completed {
            live.iter()
                .filter_map(|r| self.completed.get(r))
                .max()
                .copied()
                .unwrap_or(end)
        } else {
            end
        };
        let mut mean = PerKind::<f64>::default();
        let mut max = PerKind::<f64>::default();
        let mut max_total = 0.0f64;
        for r in &live {
            let Some(w) = self.wait.get(r.index()) else {
                continue;
            };
            for k in Kind::ALL {
                *mean.get_mut(k) += w.get(k) / live.len().max(1) as f64;
                let m = max.get_mut(k);
                *m = m.max(w.get(k));
            }
            max_total = max_total.max(w.total());
        }
        let points = self
            .points
            .into_iter()
            .map(|((b, k), acc)| {
                let (mut p, total) = (acc.summary, acc.total_wait);
                p.point = graph.point_name(b, k);
                p.kind = k.to_string();
                p.protocol = mission
                    .bound(b, k)
                    .map_or("?", |x| x.protocol.name())
                    .to_string();
                p.mean_wait = if p.decisions > 0 {
                    total / p.decisions as f64
                } else {
                    0.0
                };
                p
            })
            .collect();
        Summary {
            graph: graph.name().to_string(),
            config: graph.config_name().map(str::to_string),
            scenario: scenario.to_string(),
            seed,
            robots: n,
            outcome: match (completed, self.timeouts) {
                (true, 0) => Outcome::Completed,
                (true, _) => Outcome::CompletedWithTimeouts,
                (false, _) => Outcome::NotCompleted,
            },
            stall: None,
            chatter: None,
            completed,
            completed_robots,
            crashed_robots: n - live.len(),
            task_time: task_time.as_secs_f64(),
            interaction_time: mean,
            interaction_time_max: max,
            interaction_time_max_total: max_total,
            decisions: self.decisions,
            timeouts: self.timeouts,
            messages: self.messages,
            bytes: self.bytes,
            network,
            heartbeats: Heartbeats::default(),
            injected: BTreeMap::new(),
            dropped,
            violations: self.violations,
            invariants: crate::check::Invariants::default(),
            points,
            log_fingerprint: format!("{log_fingerprint:016x}"),
            world: None,
            sharing: None,
            versions: None,
        }
    }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let plural = |n: usize, word: &str| format!("{n} {word}{}", if n == 1 { "" } else { "s" });
        writeln!(
            f,
            "mission `{}`{} on scenario `{}`, {}, seed {}",
            self.graph,
            self.config
                .as_ref()
                .map(|c| format!(" (config `{c}`)"))
                .unwrap_or_default(),
            self.scenario,
            plural(self.robots, "robot"),
            self.seed
        )?;
        writeln!(
            f,
            "  outcome          {}  ({} of {} completed{})",
            match self.outcome {
                Outcome::NotCompleted => "NOT COMPLETED (time limit)",
                o => o.label(),
            },
            self.completed_robots,
            plural(self.robots - self.crashed_robots, "live robot"),
            if self.crashed_robots > 0 {
                format!(", {} crashed", self.crashed_robots)
            } else {
                String::new()
            }
        )?;
        if let Some(st) = &self.stall {
            writeln!(f, "  stalled          {st}")?;
        }
        writeln!(
            f,
            "  invariants       {}",
            match (&self.invariants.first, self.invariants.violations) {
                (Some(first), n) => format!("{n} VIOLATED; first: {first}"),
                (None, _) => format!("{} checked, none violated", self.invariants.checked.len()),
            }
        )?;
        if let Some(v) = &self.versions {
            writeln!(
                f,
                "  mission changes  {} handed; robots ending on {}",
                v.handed,
                v.robots
                    .iter()
                    .map(|(ver, n)| format!("version {ver}: {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )?;
        }
        writeln!(f, "  task time        {:.2} s", self.task_time)?;
        if let Some(w) = &self.world {
            let goal = match (&w.goal, w.goal_met_at) {
                (Some(g), Some(t)) => format!("{g}: met at {t:.1} s; "),
                (Some(g), None) => format!("{g}: NOT met; "),
                _ => String::new(),
            };
            writeln!(
                f,
                "  world            {goal}travelled {} m; arena covered {:.0} %{}",
                w.distance
                    .iter()
                    .map(|d| format!("{d:.1}"))
                    .collect::<Vec<_>>()
                    .join(" / "),
                w.coverage * 100.0,
                w.formation_error
                    .map(|[m, x]| format!("; formation error {m:.2} m mean, {x:.2} m max"))
                    .unwrap_or_default()
            )?;
        }
        if let Some(w) = &self.sharing {
            let get = |k: &str| w.messages.get(k).copied().unwrap_or(0);
            writeln!(
                f,
                "  world model      {}: {} messages ({} bytes): obligatory {}, helpful {}, broadcast {}; {} dropped for budget; {} beliefs adopted",
                w.policy,
                w.total(),
                w.bytes.values().sum::<u64>(),
                get("obligatory"),
                get("helpful"),
                get("broadcast"),
                w.dropped,
                w.adopted
            )?;
        }
        writeln!(
            f,
            "  interaction time {:.2} s per robot (sync {:.2}, allocation {:.2}, termination {:.2}; most for one robot {:.2})",
            self.interaction_time.total(),
            self.interaction_time.sync,
            self.interaction_time.allocate,
            self.interaction_time.terminate,
            self.interaction_time_max_total
        )?;
        writeln!(
            f,
            "  messages         {} ({} bytes): sync {}, allocation {}, termination {}",
            self.messages.total(),
            self.bytes.total(),
            self.messages.sync,
            self.messages.allocate,
            self.messages.terminate
        )?;
        writeln!(
            f,
            "  network          {} deliveries, {} lost, {} duplicated, {} cut by partitions; {} heartbeats ({} bytes)",
            self.network.delivered,
            self.network.lost,
            self.network.duplicated,
            self.network.partitioned,
            self.heartbeats.messages,
            self.heartbeats.bytes
        )?;
        if let Some(c) = &self.chatter {
            writeln!(f, "  chatter          {c}")?;
        }
        if self.timeouts > 0 || self.violations > 0 || !self.dropped.is_empty() {
            let dropped: Vec<String> = self
                .dropped
                .iter()
                .map(|(r, n)| {
                    format!(
                        "{n} {}",
                        serde_json::to_value(r)
                            .ok()
                            .and_then(|v| v.as_str().map(str::to_string))
                            .unwrap_or_default()
                    )
                })
                .collect();
            writeln!(
                f,
                "  anomalies        {} timeouts, {} protocol violations, dropped: {}",
                self.timeouts,
                self.violations,
                if dropped.is_empty() {
                    "none".to_string()
                } else {
                    dropped.join(", ")
                }
            )?;
        }
        if !self.points.is_empty() {
            let w = self
                .points
                .iter()
                .map(|p| p.point.len())
                .max()
                .unwrap_or(5)
                .max(5);
            let pw = self
                .points
                .iter()
                .map(|p| p.protocol.len())
                .max()
                .unwrap_or(8)
                .max(8);
            writeln!(
                f,
                "  {:<w$} {:<10} {:<pw$} {:>9} {:>10} {:>9} {:>9}",
                "point", "kind", "protocol", "instances", "mean wait", "messages", "timeouts"
            )?;
            for p in &self.points {
                writeln!(
                    f,
                    "  {:<w$} {:<10} {:<pw$} {:>9} {:>9.3}s {:>9} {:>9}",
                    p.point, p.kind, p.protocol, p.instances, p.mean_wait, p.messages, p.timeouts
                )?;
            }
        }
        Ok(())
    }
}

/// The world's part of the run summary.
pub fn of_world(world: &crate::physics::World) -> WorldSummary {
    WorldSummary {
        goal: world
            .spec()
            .goal
            .as_ref()
            .map(|(o, z)| format!("{o} in {z}")),
        goal_met_at: world.goal_met(),
        distance: world
            .odometers()
            .iter()
            .map(|d| (d * 100.0).round() / 100.0)
            .collect(),
        coverage: (crate::physics::coverage(world) * 1000.0).round() / 1000.0,
        formation_error: world
            .formation_error()
            .map(|(m, x)| [(m * 1000.0).round() / 1000.0, (x * 1000.0).round() / 1000.0]),
        first_seen: (world.spec().objects.iter().enumerate())
            .filter_map(|(k, o)| {
                let t = world.first_seen(k)?;
                Some((o.name.clone()?, (t * 1000.0).round() / 1000.0))
            })
            .collect(),
    }
}
