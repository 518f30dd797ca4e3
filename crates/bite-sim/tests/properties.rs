//! Property tests over random valid behavior graphs, team sizes 1-12,
//! random protocol bindings, network faults (loss, duplication, jitter,
//! reordering) and robots that crash or pause.
//!
//! Properties, checked on every run (see `bite_sim::check`):
//! - agreement: all members of a subteam select the same successor;
//! - allocation covers every child that some member can take and gives
//!   each member exactly one child;
//! - no robot keeps running a behavior its subteam ended;
//! - every run ends — completion, or a reported protocol timeout — within
//!   the time limit.
//!
//! A graph is generated from a seed, as YAML text (so the loader is
//! exercised too). On failure the graph and scenario are written under
//! `target/proptest-failures/` and the message gives the command that
//! replays the run.

use bite_core::graph::load_str;
use bite_core::interaction::Rng;
use bite_sim::check::check;
use bite_sim::runner::RunOptions;
use bite_sim::{Scenario, prepare, run};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use std::fmt::Write as _;

mod common;
use std::path::PathBuf;
use std::sync::Arc;

/// A generated mission: graph and scenario text.
#[derive(Debug, Clone)]
struct Generated {
    graph: String,
    scenario: String,
}

struct Gen {
    rng: Rng,
    behaviors: Vec<String>,
    skills: Vec<String>,
    facts: usize,
    events: Vec<String>,
    next_id: usize,
    /// Team size.
    robots: usize,
    /// Divergent mode: termination conditions become true for random
    /// subsets of the members, at random times, and facts that
    /// preconditions read differ from robot to robot.
    divergent: bool,
}

impl Gen {
    fn name(&mut self, prefix: &str) -> String {
        self.next_id += 1;
        format!("{prefix}{}", self.next_id)
    }
    fn team(&mut self) -> &'static str {
        if self.rng.random_bool(0.8) {
            "true"
        } else {
            "false"
        }
    }
    fn sync(&mut self) -> &'static str {
        const ALL: [&str; 6] = [
            "sync.by-rule",
            "sync.vote",
            "sync.ranked-vote",
            "sync.leader",
            "sync.elected-leader",
            "sync.round-robin",
        ];
        ALL[self.rng.random_range(0..ALL.len())]
    }
    fn term(&mut self) -> &'static str {
        const ALL: [&str; 5] = [
            "term.local",
            "term.wait-all",
            "term.wait-all",
            "term.majority",
            "term.first-wins",
        ];
        ALL[self.rng.random_range(0..ALL.len())]
    }
    fn alloc(&mut self) -> &'static str {
        const ALL: [&str; 6] = [
            "alloc.by-id",
            "{ protocol: alloc.by-value, params: { value: heading } }",
            "{ protocol: alloc.by-attribute, params: { attribute: colour } }",
            "alloc.optimal",
            "alloc.auction",
            "alloc.token",
        ];
        ALL[self.rng.random_range(0..ALL.len())]
    }

    /// An atomic behavior that ends when its timed skill completes.
    fn atomic(&mut self, name: &str, pre: Option<String>, next: &[String], members: Option<&str>) {
        let (lo, hi) = (
            self.rng.random_range(0.2..4.0),
            self.rng.random_range(4.0..9.0),
        );
        self.skills.push(format!(
            "  s_{name}: {{ duration: [{lo:.2}, {hi:.2}], start: {{ {name}_done: false }}, done: {{ {name}_done: true }} }}"
        ));
        let team = self.team();
        let mut b =
            format!("  {name}:\n    team: {team}\n    skill: s_{name}\n    until: {name}_done\n");
        self.finish(&mut b, pre, next, members);
        self.behaviors.push(b);
    }

    fn finish(
        &mut self,
        b: &mut String,
        pre: Option<String>,
        next: &[String],
        members: Option<&str>,
    ) {
        if let Some(p) = pre {
            let _ = writeln!(b, "    pre: '{p}'");
        }
        if !next.is_empty() {
            let _ = writeln!(b, "    next: [{}]", next.join(", "));
            if next.len() >= 2 && self.rng.random_bool(0.5) {
                let s = self.sync();
                let _ = writeln!(b, "    sync: {s}");
            }
        }
        if let Some(m) = members {
            let _ = writeln!(b, "    members: \"{m}\"");
        }
        if self.rng.random_bool(0.3) {
            let t = self.term();
            let _ = writeln!(b, "    terminate: {t}");
        }
    }

    /// A precondition on a fact that is the same for every robot all run
    /// long, so that silent protocols agree.
    fn fact_pre(&mut self) -> Option<String> {
        if self.facts == 0 || !self.rng.random_bool(0.4) {
            return None;
        }
        let f = self.rng.random_range(0..self.facts);
        Some(if self.rng.random_bool(0.5) {
            format!("f{f}")
        } else {
            format!("not f{f}")
        })
    }

    /// An execution chain; returns its head.
    fn chain(&mut self, depth: usize, members: Option<&str>) -> String {
        let len = self.rng.random_range(1..=3);
        let names: Vec<String> = (0..len).map(|_| self.name("b")).collect();
        let cycle = len >= 2 && self.rng.random_bool(0.3);
        for i in 0..len {
            let name = names[i].clone();
            let mut next: Vec<String> = names.get(i + 1).cloned().into_iter().collect();
            // A choice point: an alternative successor that rejoins the chain.
            if i + 1 < len && self.rng.random_bool(0.35) {
                let alt = self.name("alt");
                let rejoin: Vec<String> = names.get(i + 2).cloned().into_iter().collect();
                let pre = self.fact_pre();
                self.atomic(&alt, pre, &rejoin, None);
                next.push(alt);
            }
            if cycle && i + 1 == len {
                next.push(names[0].clone());
            }
            // The head of a chain that cycles is bounded by its run count;
            // the head of any chain takes its `members` constraint.
            let pre = if i == 0 && cycle {
                Some(format!("runs < {}", self.rng.random_range(2..4)))
            } else if i > 0 {
                self.fact_pre()
            } else {
                None
            };
            let m = if i == 0 { members } else { None };
            if depth < 3 && self.rng.random_bool(0.45) {
                self.composite(&name, depth, pre, &next, m);
            } else {
                self.atomic(&name, pre, &next, m);
            }
        }
        names[0].clone()
    }

    /// A behavior decomposed into one to three execution chains.
    fn composite(
        &mut self,
        name: &str,
        depth: usize,
        pre: Option<String>,
        next: &[String],
        members: Option<&str>,
    ) {
        let k = self.rng.random_range(1..=3);
        let mut heads = Vec::new();
        for _ in 0..k {
            let m = match self.rng.random_range(0..4) {
                0 => Some("1"),
                1 => Some("1.."),
                2 => Some("2.."),
                _ => None,
            };
            heads.push(self.chain(depth + 1, if k >= 2 { m } else { None }));
        }
        let team = self.team();
        let mut b = format!(
            "  {name}:\n    team: {team}\n    children: [{}]\n",
            heads.join(", ")
        );
        if k >= 2 && self.rng.random_bool(0.6) {
            let a = self.alloc();
            let _ = writeln!(b, "    allocate: {a}");
        }
        if self
            .rng
            .random_bool(if self.divergent { 0.5 } else { 0.25 })
        {
            // Sometimes the parent ends on a global fact, cutting its chains
            // short; in divergent mode it becomes true for some members
            // only, each at its own time.
            let g = self.events.len();
            if self.divergent {
                for r in 0..self.robots {
                    if self.rng.random_bool(0.5) {
                        let at = self.rng.random_range(1.0..60.0);
                        self.events.push(format!(
                            "  - {{ at: {at:.1}s, robots: [r{r}], set: {{ g{g}: true }} }}"
                        ));
                    }
                }
            } else {
                let at = self.rng.random_range(3.0..60.0);
                self.events
                    .push(format!("  - {{ at: {at:.1}s, set: {{ g{g}: true }} }}"));
            }
            let _ = writeln!(b, "    until: g{g}");
        }
        self.finish(&mut b, pre, next, members);
        self.behaviors.push(b);
    }
}

fn generate(seed: u64, robots: usize, loss: f64, dup: f64, jitter_ms: u64) -> Generated {
    generate_with(seed, robots, loss, dup, jitter_ms, false)
}

fn generate_with(
    seed: u64,
    robots: usize,
    loss: f64,
    dup: f64,
    jitter_ms: u64,
    divergent: bool,
) -> Generated {
    let mut g = Gen {
        rng: Rng::seed_from_u64(seed),
        behaviors: Vec::new(),
        skills: Vec::new(),
        facts: 3,
        events: Vec::new(),
        next_id: 0,
        robots,
        divergent,
    };
    let sync = g.sync();
    let term = g.term();
    let facts: Vec<String> = (0..g.facts)
        .map(|i| format!("f{i}: {}", g.rng.random_bool(0.5)))
        .collect();
    g.composite("root", 0, None, &[], None);
    if divergent {
        // Each robot perceives the facts its own way from the start, and
        // some perceptions change later, robot by robot: silent rules split
        // and the team must heal.
        for r in 0..robots {
            for f in 0..g.facts {
                if g.rng.random_bool(0.3) {
                    let at = if g.rng.random_bool(0.5) {
                        0.0
                    } else {
                        g.rng.random_range(1.0..40.0)
                    };
                    let v = g.rng.random_bool(0.5);
                    g.events.push(format!(
                        "  - {{ at: {at:.1}s, robots: [r{r}], set: {{ f{f}: {v} }} }}"
                    ));
                }
            }
        }
    }
    let graph = format!(
        "graph: random-{seed}\nteam: {{ robots: {robots} }}\nstart: root\n\
         defaults: {{ sync: {sync}, allocate: alloc.by-id, terminate: {term} }}\n\
         beliefs: {{ {} }}\nbehaviors:\n{}",
        facts.join(", "),
        g.behaviors.join("")
    );
    // Sometimes a robot crashes for good, or pauses for less than the
    // failure detector's bound. (Long pauses, where a robot presumed lost
    // comes back, are covered by the scenario tests: with random graphs
    // they still have known failure modes, see docs/protocols.md.)
    let crash = if !divergent && robots >= 2 && g.rng.random_bool(0.3) {
        let r = g.rng.random_range(0..robots);
        let at = g.rng.random_range(0.5..60.0);
        let until = if g.rng.random_bool(0.5) {
            format!(", until: {:.2}s", at + g.rng.random_range(0.2..1.5))
        } else {
            String::new()
        };
        format!("crashes:\n  - {{ robot: r{r}, at: {at:.2}s{until} }}\n")
    } else {
        String::new()
    };
    let scenario = format!(
        "scenario: random-{seed}\nseed: {seed}\ncontrol_hz: 10\ntime_limit: 1500s\n\
         network: {{ latency: 2ms, jitter: {jitter_ms}ms, loss: {loss}, duplicate: {dup} }}\n\
         skills:\n{}\n{}{crash}",
        g.skills.join("\n"),
        if g.events.is_empty() {
            String::new()
        } else {
            format!("events:\n{}\n", g.events.join("\n"))
        }
    );
    Generated { graph, scenario }
}

/// Save a failing case and return the command that replays it.
fn save_failure(seed: u64, case: &Generated) -> String {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/proptest-failures");
    let _ = std::fs::create_dir_all(&dir);
    let gp = dir.join(format!("random-{seed}.yaml"));
    let sp = dir.join(format!("random-{seed}-scenario.yaml"));
    let _ = std::fs::write(&gp, &case.graph);
    let _ = std::fs::write(&sp, &case.scenario);
    format!("bite run {} --scenario {}", gp.display(), sp.display())
}

fn run_case(
    seed: u64,
    robots: usize,
    loss: f64,
    dup: f64,
    jitter_ms: u64,
) -> Result<(), TestCaseError> {
    run_generated(seed, robots, loss, dup, jitter_ms, false)
}

fn run_generated(
    seed: u64,
    robots: usize,
    loss: f64,
    dup: f64,
    jitter_ms: u64,
    divergent: bool,
) -> Result<(), TestCaseError> {
    let case = generate_with(seed, robots, loss, dup, jitter_ms, divergent);
    let graph = match load_str(&Arc::from(format!("random-{seed}.yaml")), &case.graph) {
        Ok(g) => g,
        Err(d) => {
            let cmd = save_failure(seed, &case);
            return Err(TestCaseError::fail(format!(
                "generated graph invalid: {d}\nreplay: {cmd}"
            )));
        }
    };
    let sc = Scenario::load_str(&Arc::from("scenario.yaml"), &case.scenario)
        .map_err(|d| TestCaseError::fail(format!("generated scenario invalid: {d}")))?;
    let mission = prepare(&graph, &sc, None, &bite_protocols::registry())
        .map_err(|d| TestCaseError::fail(format!("{d}")))?;
    let report = run(
        mission.clone(),
        &sc,
        RunOptions {
            record: true,
            ..RunOptions::default()
        },
    )
    .map_err(|d| TestCaseError::fail(format!("{d}")))?;
    let violations = check(&report, &mission);
    let s = &report.summary;
    // Every mission completes within the time limit, faults or not: a
    // timeout is a decision, never a hang; faults may only cost time.
    let ended = s.completed;
    // Without faults, no protocol instance ever needs its deadline: nobody
    // waits across levels, and splits heal.
    let clean = !divergent || s.timeouts == 0;
    if !violations.is_empty() || !ended || s.violations > 0 || !clean {
        let cmd = save_failure(seed, &case);
        return Err(TestCaseError::fail(format!(
            "seed {seed}, {robots} robots, loss {loss}, dup {dup}, jitter {jitter_ms}ms\n{s}\n\
             violations:\n{}\nreplay: {cmd}",
            violations
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join("\n")
        )));
    }
    Ok(())
}

proptest! {
    #![proptest_config(common::config(64))]

    /// No faults, but termination conditions that become true for random
    /// subsets of the members at random times, and perceptions that differ
    /// from robot to robot: no instance ever reaches its deadline (nobody
    /// waits across levels, splits heal), every invariant holds, every run
    /// completes.
    #[test]
    fn no_waiting_across_levels(seed in any::<u64>(), robots in 1usize..=8) {
        run_generated(seed, robots, 0.0, 0.0, 3, true)?;
    }

    /// Fault-free network: every invariant holds and every run completes.
    #[test]
    fn random_teams_agree_and_complete(seed in any::<u64>(), robots in 1usize..=12) {
        run_case(seed, robots, 0.0, 0.0, 3)?;
    }

    /// Loss, duplication and reordering up to 30%: invariants still hold,
    /// and every run ends (completion or a reported timeout).
    #[test]
    fn random_teams_survive_network_faults(
        seed in any::<u64>(),
        robots in 1usize..=12,
        loss in prop_oneof![Just(0.0), 0.0f64..0.3],
        dup in prop_oneof![Just(0.0), 0.0f64..0.3],
        jitter in 0u64..200,
    ) {
        run_case(seed, robots, loss, dup, jitter)?;
    }
}

#[test]
fn generated_graphs_exercise_every_structure() {
    // The generator must produce what the properties are about: allocation
    // points, synchronization points, sequential cycles, nested allocation.
    let mut alloc = 0;
    let mut sync = 0;
    let mut cycles = 0;
    for seed in 0..40 {
        let g = generate(seed, 4, 0.0, 0.0, 3);
        let graph = load_str(&Arc::from("g.yaml"), &g.graph)
            .unwrap_or_else(|d| panic!("seed {seed}: {d}\n{}", g.graph));
        for p in graph.points() {
            match p.kind {
                bite_core::msg::Kind::Allocate => alloc += 1,
                bite_core::msg::Kind::Sync => sync += 1,
                _ => {}
            }
        }
        cycles += usize::from(g.graph.contains("runs <"));
    }
    assert!(
        alloc > 20 && sync > 20 && cycles > 5,
        "alloc {alloc}, sync {sync}, cycles {cycles}"
    );
}

/// Cases the properties once failed, run on every test run whatever the
/// sampled seeds (each names the section of docs/reliability.md that tells
/// what failed and what changed).
#[test]
fn cases_that_failed_once() {
    // "An allocation left undecided": a member done with an `alloc.token`
    // behavior before its first round decided; the leader waited for it,
    // then passed tokens for places nobody could take, until its deadline.
    run_generated(7_844_512_826_741_064_117, 4, 0.0, 0.0, 3, true)
        .unwrap_or_else(|e| panic!("{e}"));
    // The same graph with five robots: a member that ended the individual
    // behavior above its subteam dissolved the subteam; its teammate still
    // in it asked it at the next synchronization, heard nothing (a dead
    // team's messages were dropped as stale) and waited until its
    // deadline.
    run_generated(7_844_512_826_741_064_117, 5, 0.0, 0.0, 3, true)
        .unwrap_or_else(|e| panic!("{e}"));
    // "A teammate behind in an individual behavior": a robot done with two
    // individual behaviors while its teammates were still in the first
    // took theirs for a diverged history and led the team back into it,
    // for ever (no faults; NOT COMPLETED at the time limit).
    run_case(17_943_441_955_658_021_061, 3, 0.0, 0.0, 3).unwrap_or_else(|e| panic!("{e}"));
    // "A teammate nobody heard": a leader that left its subteam alone
    // (six robots), members a lap behind that had not made the allocation
    // their teammate waited in, and teammates that had ended the behavior
    // a member waited below (five robots, the last): each waited out a
    // deadline for a teammate that did not send it its heartbeats.
    for (seed, robots) in [
        (7_844_512_826_741_064_117, 6),
        (8_549_300_477_484_552_168, 5),
        (7_866_632_090_392_478_126, 8),
        (9_518_102_418_678_138_062, 8),
        (718_802_077_212_583_624, 7),
        (16_977_040_845_566_393_922, 5),
        // "A decision made before the late arrivals came": robots a lap
        // behind started an allocation their leader had decided before
        // it left (eight robots, then seven); the robot leading in its
        // place ignored the decision the teammates that applied it told
        // it, and waited them out.
        (15_936_183_023_725_379_530, 8),
        (1_284_632_012_593_473_574, 7),
        // "A leader a lap behind": two members took one subteam from
        // different views of the allocation above and waited in it for
        // their leader, a lap behind, hearing only it.
        (1_189_108_377_300_224_787, 7),
        // The same with the leader behind inside the team: at a point
        // where a silent rule saw different options, one member took
        // another successor than two others, and all three heard only
        // the leader, still running the behavior before the point.
        (17_570_084_640_527_683_413, 8),
        // "A contribution sent to the leader before": two members ended
        // the behavior just after contributing to leaders that were
        // leaving too; the robot that led next waited for them.
        (3_090_137_497_910_363_889, 7),
        // "A teammate that went past without running it": two members a
        // lap behind converged on their leader's next execution, skipping
        // the one a teammate waited in for them; nothing told it.
        (16_356_430_973_488_520_355, 6),
        // "A place claimed twice": two members lost a race for a place
        // (`alloc.token`) and took no more tokens; the leader waited for
        // them.
        (10_877_919_030_516_264_622, 7),
        // "A deadline just after the leader changed": a member waited
        // out leaders heard at work on the way to the point; its deadline
        // fell a few milliseconds after the last of them left, before the
        // next one could gather the team (seven robots, then eight).
        (14_359_459_491_020_814_629, 7),
        (4_884_531_164_592_028_632, 8),
        // "A teammate waiting past the execution a robot runs": a vote's
        // coordinator waited out two members still in the individual
        // behavior before it, whose heartbeats went to the team's leader.
        (14_151_179_637_200_551_742, 6),
        // "A teammate many behaviors behind": a leader counted a teammate
        // two behaviors behind as silent, having ended more than eight
        // executions since the one the teammate ran.
        (16_216_504_317_419_966_665, 5),
        // "A decision from a leader that left": the coordinator of a
        // synchronization decided, applied and left; a member on its way
        // found the decision waiting, then led without it and chose
        // another successor (seven robots, then eight).
        (10_533_492_770_770_632_144, 7),
        (15_129_041_871_835_573_196, 8),
        // "A root leader that finished": the root team's leader finished
        // the mission and relayed nothing more; members that had heard of
        // different finished teammates made different silent allocations,
        // round after round, and waited for each other's subteams.
        (14_038_951_268_081_933_415, 8),
        // The same section, what the relay brought out: a member a lap
        // behind allocated knowing that a teammate had finished since its
        // leader allocated; the leader's deadline fell before the split
        // was seen.
        (3_675_743_155_736_443_249, 7),
        // "Both sides of a split waiting at a termination": a member that
        // came late took its subteam from a later view of the silent
        // allocation above and ended it at once; it and its leader each
        // waited at their own subteam's termination for the other.
        (15_491_346_240_280_064_998, 5),
        // "A follower a lap short in its counts": a robot that followed a
        // teammate into its execution after the same predecessor kept its
        // own, lower count of a team behavior of the loop, numbered its
        // next run of it one lower, and at the next point took the
        // teammate on its way there for one gone round past (seven
        // robots). With six, "A teammate in the execution a robot
        // converged past" (not fixed): the counts taken on change the
        // run from 58.5 s, and the case it traced does not arise.
        (13_366_699_504_392_707_480, 7),
        (12_862_965_036_356_564_799, 6),
        // "Laps of an individual behavior taken for laps past": a robot at
        // an allocation after its run of an individual behavior took a
        // teammate in a later-numbered run of it (the same lap, numbered
        // at the teammate's own pace) for one gone round past, left it
        // out, and both sides' deadlines fell.
        (2_799_136_479_243_646_113, 5),
        // "A teammate seen on the other side of a split": the healing
        // leader, at an allocation, saw a member take another successor
        // after the same execution, and its deadline fell before the
        // member came over.
        (541_206_029_754_869_826, 6),
        // "A split seen from a synchronization": a member waited at its
        // subteam's synchronization for a leader that came to the
        // allocation above and allocated from another view.
        (8_970_543_473_821_155_539, 7),
        // "A coordinator that left undecided, unheard": a robot waiting at
        // an allocation whose leader had left the execution heard nobody
        // still in it; its coordinator came, left undecided on its own
        // condition, and went on, and nobody asked it how it ended.
        (183_384_660_120_993_347, 7),
        // "A coordinator that left undecided, heard": members waiting at an
        // allocation whose leader had ended the execution by its own
        // condition did not hear their coordinator (seed 2634); a member
        // whose coordinator took over half a second before the deadline,
        // already gone on, timed out before it asked it (seed 343).
        (14_719_798_549_285_451_198, 8),
        (12_850_264_291_869_646_365, 7),
        // "A lap renamed behind a robot that left it": a member that ran an
        // individual behavior's lap under an id the team then burned was
        // not taken for gone past the lap's next id (seed 1283); and a
        // member that left a lap its teammates renamed afterwards numbered
        // its next lap with the new name (seed 377 of the first attempt).
        (1_510_455_449_266_984_623, 7),
        (13_085_922_093_764_180_830, 8),
        // "Teammates gone another way": a robot a lap ahead waited at an
        // allocation for a teammate it never heard (it answers now); a
        // teammate on another way into the point's execution (awaited); a
        // contribution dropped by a coordinator that did not know yet that
        // it led (asked again); teammates that went past an execution
        // without running it, or ended it before its allocation (left out
        // of its points); members late into an execution whose leaders had
        // left it, sending to one that did not answer (answered).
        (1_730_459_986_348_358_178, 4),
        (2_090_918_748_688_623_487, 5),
        (7_180_224_004_388_772_354, 8),
        (9_461_620_870_857_060_531, 6),
        (2_527_497_076_677_607_155, 6),
        (15_863_011_668_451_335_064, 5),
        (5_261_739_610_812_070_048, 7),
        // The same section, a first form that took a teammate in the
        // execution before this robot's (which it had converged past) for
        // one that went past its execution.
        (16_540_400_953_571_571_815, 8),
        // And one that took a teammate in another successor of this
        // robot's behavior's earlier execution, on its way round a cycle
        // back, for one past it.
        (15_465_759_569_787_062_651, 5),
        // A deadline falling with counted teammates never heard: their
        // heartbeats went to a leader that had left (called now).
        (12_254_330_314_479_522_449, 6),
        (12_254_330_325_892_256_918, 6),
        (14_026_682_046_967_156_622, 7),
        // "A contribution sent to a coordinator that left": a member sent
        // its value to a coordinator that then finished the mission, and
        // left the allocation; the robot that led from the start waited
        // for it (asked now).
        (4_293_902_327_213_708_843, 7),
        // "A call dropped at a takeover": members that dropped a new
        // coordinator's first call, or asked a coordinator that had left
        // the point, on a schedule backed off to seconds (six robots,
        // then eight, twice).
        (1_069_055_035_715_906_447, 6),
        (8_753_189_644_158_184_162, 8),
        (15_927_605_051_834_793_304, 8),
        // "A coordinator after one that left, from the start": a first
        // form had every robot that led after a teammate that left decide
        // nothing as it left the point, also when that teammate had left
        // long before without running it; members waited for a
        // coordinator that had gone.
        (13_855_237_196_121_962_963, 8),
        // "A coordinator still on its way to the allocation above": a
        // member waited for its leader, heard in the execution above the
        // point's without a place in the point's team yet (a lap behind,
        // it had not made that allocation); the member's deadline fell
        // while the leader was on its way.
        (1_198_008_881_174_613_944, 6),
        // "A teammate gone round past the execution": a robot a lap behind
        // in `b1`#2 waited at an allocation below it for teammates in
        // `b3`#2 (which it came to `b1`#2 after `b3`#1), taken for ones on
        // their way into it, and the run stalled.
        (5_857_852_094_645_335_443, 6),
        // "A release from a teammate that left": a robot came to a
        // `term.majority` point just after its team had ended it, counted
        // the teammate that released the team out, ignored its release and
        // ran the behavior 85 s after its team had ended it.
        (16_345_115_294_303_735_707, 8),
        // "Members ahead of their leader": two members past their leader
        // chose `alt4` and `b2` after the individual `b1`#3, each heard
        // only the leader, a lap behind, and ran apart for 6.5 s.
        (15_725_357_882_910_428_641, 6),
        // "A split the other side went through": r1 took `b2` after `b1`#1,
        // its team `alt4`, which r0 passed at once on its teammates'
        // releases; r1 waited alone in `b2` for 121 s, r0 at four points
        // for it.
        (5_063_174_684_227_258_361, 5),
        (10_981_569_113_438_498_380, 6),
        (13_945_246_781_331_279_317, 7),
        // "Heard at the barrier when the deadline fell": r7 reached `b45`'s
        // barrier and reported to teammates that had left; r3, leading
        // it, had heard r7 waiting there but timed out 30 ms before r7
        // found it.
        (10_985_443_681_506_886_131, 8),
        // "Laps of an individual behavior": a robot a lap behind burned
        // its team's next run of a behavior for a teammate's lap of the
        // individual one after it (r2 alone at `b2`#4's majority); a
        // robot took a teammate two edges back in an individual behavior
        // for one elsewhere (an auction's deadline); robots at work, whose
        // heartbeats went to a leader gone elsewhere, were taken for
        // silent at their execution's synchronization (three deadlines).
        (5_046_127_393_119_846_478, 3),
        (10_264_868_072_022_678_513, 5),
        (5_507_922_443_524_571_597, 8),
        // "A teammate gone on beyond the execution": r3 and r5 ended
        // `b33`#2 at once by its own condition and ran `b34`#2 into
        // `b35`#2; r2, later into `b33`#2, waited at `b37`#2's
        // `term.wait-all` for them, their end of `b33`#2 gone from the ends
        // they reported.
        (12_562_543_272_125_157_407, 8),
        // The same section, its first form: a member that took an
        // individual behavior's other successor by its own precondition,
        // and converged back a moment later, was taken for one gone on
        // beyond its team's execution and left out of it (an allocation
        // split, then a synchronization's deadline).
        (3_518_242_391_574_278_183, 6),
        // "A member that found its coordinator gone at the point": members
        // that reached an `alloc.auction` late bid to a coordinator that
        // had left it (they had not heard it leave), learnt so from its
        // answer, and waited for the new coordinator's next call, which
        // came after its deadline (property seed 2648 of the fifth
        // session of 2026-12-06).
        (12_240_106_986_188_585_820, 7),
        // The same section, seed 2677: a robot a lap ahead had ended more
        // executions since it left `b22`#1 (before its synchronization)
        // than it remembers, and kept its teammate's question about that
        // synchronization for ever instead of answering that it had left.
        (8_310_571_936_956_924_643, 5),
        // "Property seeds 2,638 to 3,553", seed 3136: a robot converged
        // into the execution after its teammate's (its count was past
        // the teammate's, from a third teammate's word), and "the higher
        // epoch wins" drew the team up after it, epoch after epoch, until
        // the stall watch ended the run.
        (12_706_380_029_821_677_148, 8),
        // "A coordinator that went past the allocation", seeds 3251 and
        // 3973: a coordinator converged onto a teammate past an
        // `alloc.by-value` / `alloc.by-attribute` execution it never ran,
        // and kept its members' questions about it for ever; they waited
        // out their deadline.
        (7_843_099_851_630_415_988, 7),
        (16_386_558_250_385_141_952, 6),
        // "A member asked for a decision it applied", seed 4167: robots
        // that reached an `alloc.by-value` point after its coordinator had
        // decided and left asked a member that had applied the decision,
        // which kept quiet (it was no coordinator in its own view).
        (4_632_419_412_741_304_454, 4),
        // "A leader gone off for good", seeds 5140, 4646, 4021 and 3003:
        // the team's first member (or a member with it) went off into an
        // individual behavior that never leads back, from an execution
        // before the one a teammate waited in; the teammate waited for it
        // at that execution's points until their deadlines.
        (5_028_977_122_179_993_407, 8),
        (1_642_720_823_527_748_982, 7),
        (7_887_722_685_423_016_364, 8),
        (15_105_780_659_358_193_082, 5),
        // "A member that ended ahead of its team", seed 5212: two
        // members ended a team behavior by its own `until`, ahead of the
        // team (a `term.majority` that decided a minute later), and left
        // the subteam below it; its leader, which they no longer sent
        // heartbeats to, waited for them at its next point until its
        // deadline. Seed 5839 (four robots, two deadlines)
        // passed with the same change.
        (10_512_915_990_778_792_624, 7),
        (16_918_095_872_503_224_342, 4),
        // "Members past a split, unheard", seed 3859: two members chose
        // apart after a silent `sync.by-rule` while the leader and two
        // other members were still before the point; each sent its
        // heartbeats to the leader and to a member behind, which did not
        // answer, and the two ran their successors side by side for 5.8
        // s (`splits-healed`).
        (5_905_993_687_803_114_408, 7),
        // "A teammate a lap ahead, converged past", seed 6239: a robot a
        // lap behind, in `b31`#1, waited out an `alloc.auction`'s deadline
        // below it for a teammate that had converged past `b31`#1 onto the
        // team's `b31`#2, come another way.
        (11_787_103_274_286_648_411, 6),
        // "A teammate on the other way, two edges back", seed 6286: a
        // member at an auction waited out its deadline for its
        // coordinator, slow on the other successor of the point before,
        // two sequential edges from the auction's behavior. Seed 4412
        // (four robots) passes with the same change.
        (7_004_174_605_040_164_135, 7),
        (4_474_642_605_013_233_406, 4),
        // "A member that reached the token's point late", seed 6855: a
        // member came to an `alloc.token` point 44 s after its tokens were
        // dealt (it dropped them), asked, and waited for the leader's next
        // deal, a backoff away; the leader's deadline came first.
        (8_450_988_898_213_553_314, 8),
        // "A leader gone off from an individual behavior", seed 6404: a
        // member waited at an individual behavior's auction for its
        // coordinator, the team's first member, gone into a team behavior
        // that ends the root's chain.
        (859_933_712_933_106_335, 8),
        // "A token of an earlier deal", seed 7260: a member claimed a
        // place of an earlier leader's deal, passed on to it before the
        // leadership changed; the new leader took the claim for a protocol
        // violation and waited for the member until its deadline.
        (6_026_314_665_237_865_797, 7),
        // "A teammate allocating two levels up", seed 7435: a barrier's
        // leader took a teammate making the allocation of the point's
        // grandparent for silent and decided on its deadline, 0.1 s after
        // the teammate came down.
        (16_022_569_825_119_803_579, 8),
        // "A teammate behind the execution converged past", seeds 7621 and
        // 6662: robots a lap behind converged onto a teammate's execution
        // after one they never ran, and took a teammate still in that one
        // for a teammate elsewhere (at an allocation, its deadline decided
        // without it); counted as passed, they no longer answered it where
        // it waited for them. 3038, 5199 and 6166 pass since the same two
        // changes.
        (7_437_662_065_035_196_631, 5),
        (10_620_271_608_133_783_173, 8),
        (7_971_561_576_938_882_804, 8),
        (16_496_831_448_393_991_138, 3),
        (8_177_170_296_156_092_438, 6),
        // "A teammate converged past an allocation it never started", seed
        // 7816: r4 converged from `b2`#1 onto its teammates' `b2`#2, past
        // `b1`#2, whose `alloc.optimal` r0 coordinated; r0 waited 14.5 s
        // for r4's costs, until its deadline.
        (216_557_608_976_084_570, 6),
        // "A teammate waiting at the end of a successor", seed 7900: r2,
        // in `b4`#4 after `b3`#3, waited at its `term.majority` for
        // teammates that waited for it at `b3`#4's `sync.elected-leader`,
        // until a deadline, twice in the run.
        (11_260_683_622_264_470_111, 4),
        // "Following a teammate through its ends, past what came after",
        // seed 8310: r5 followed r0 into `alt4`#2 and counted past `b3`#2,
        // which came after it; r0 waited for it at `b1`#3's allocation.
        (15_285_885_989_656_780_006, 6),
    ] {
        run_generated(seed, robots, 0.0, 0.0, 3, true).unwrap_or_else(|e| panic!("{e}"));
    }
    // The same section, its first form: a member waited on its leader in
    // the execution above in another of its subteams; after a crash two
    // robots, each in a subteam the other had not taken (one leading its
    // own, the other a member of the other's), waited for each other for
    // ever (NOT COMPLETED at the time limit).
    run_case(11_211_088_363_829_428_195, 5, 0.0, 0.0, 3).unwrap_or_else(|e| panic!("{e}"));
    // "An individual successor is no split": after an individual behavior
    // one robot, its perception differing, took an individual successor
    // while its teammates took the team one; the checker took the two for
    // a split that did not heal.
    run_generated(15_873_932_308_788_952_267, 8, 0.0, 0.0, 3, true)
        .unwrap_or_else(|e| panic!("{e}"));
    // "A teammate many behaviors behind": a member done with a
    // `term.local` decomposition went on alone through more than eight
    // behaviors, took its leader, still in the decomposition, for a
    // diverged history and went back into it, and the two restarted the
    // decomposition every lap (no faults; NOT COMPLETED at the time limit).
    run_case(9_820_052_158_066_147_912, 6, 0.0, 0.0, 0).unwrap_or_else(|e| panic!("{e}"));
    // The same, under 27 % loss: members that adopted the decision of a
    // coordinator that had left, while their new coordinator, which had
    // not heard it, decided anew, held another allocation than it.
    run_case(
        29_773_664_256_678_449,
        11,
        0.269_041_931_899_805_63,
        0.0,
        20,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    // "A coordinator that took over and left": the old coordinator's
    // heartbeat overtook its announcement (126 ms jitter); the member that
    // took over left the point 23 ms later and announced an allocation of
    // its own, which parted the members.
    run_case(
        12_199_998_743_731_976_875,
        5,
        0.025_405_893_691_245_112,
        0.0,
        126,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    // "A coordinator after one that left, from the start": the robot
    // that led an allocation from its start, the teammate before it
    // having run it and left (its announcement delayed by 188 ms of
    // jitter, or lost under 18 % loss), left the point too and announced
    // an allocation of its own, which parted the members.
    run_case(5_998_380_625_315_892_372, 8, 0.0, 0.0, 188).unwrap_or_else(|e| panic!("{e}"));
    run_case(
        14_989_542_626_833_434_280,
        9,
        0.182_607_040_968_245_12,
        0.0,
        34,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    run_case(
        10_325_446_998_601_771_183,
        10,
        0.180_472_260_260_426_2,
        0.0,
        84,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    // "A token from a teammate left out": a member claimed, from the
    // leader, a place another leader's deal had numbered (a protocol
    // violation reported, no faults).
    run_case(12_281_959_434_284_252_109, 7, 0.0, 0.0, 3).unwrap_or_else(|e| panic!("{e}"));
}
