//! Scripted protocol tests, in the style of etcd's raft tests: the robots'
//! minds (`bite_agent::Agent`) run one coordination point under one
//! protocol, and a script decides the fate of every message they send —
//! delivered, lost, duplicated, held back until after the deadline — and
//! what else arrives (a message from a robot outside the team, an old
//! message of another instance). The test then says what every robot
//! decided. Every one of the library's protocols runs every script.
//!
//! The mission around the point is the one `bite bench protocols` probes
//! (`bite_sim::probe::mission_text`): sync among 3 successors, allocation
//! among 3 children, termination of a 1 s behavior; 3 robots. Time is
//! simulated: control ticks at 10 Hz, 10 ms latency.

use bite_agent::agent::{Agent, AgentOutput, Input};
use bite_agent::scenario::Scenario;
use bite_core::event::Event;
use bite_core::ids::RobotId;
use bite_core::interaction::Recipients;
use bite_core::msg::Envelope;
use bite_core::time::Time;
use bite_sim::probe::{LIBRARY, ProbeSpec, mission_text};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

/// What happens to one copy of a message (one sender, one recipient).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fate {
    Deliver,
    Drop,
    /// Delivered twice.
    Duplicate,
    /// Delivered this much later than the latency.
    Hold(Duration),
}

/// One copy on the network (one recipient): who sent it, and whether it
/// belongs to the point under test.
#[derive(Clone, Debug)]
struct Copy {
    from: usize,
    at_point: bool,
}

/// What one robot decided at the point under test.
#[derive(Clone, Debug, PartialEq)]
struct Decision {
    outcome: serde_json::Value,
    timed_out: bool,
    at: Time,
}

struct Run {
    protocol: &'static str,
    /// Behavior ids of the probe's successors and children, by name.
    ids: BTreeMap<String, u32>,
    decisions: BTreeMap<usize, Vec<Decision>>,
    completed: Vec<bool>,
}

/// Extra inputs a script hands the robots: called at every step with the
/// time, the robots and every message sent so far.
type Inject<'a> = dyn FnMut(Time, &mut Vec<Agent>, &[Envelope]) + 'a;

const LATENCY: Duration = Duration::from_millis(10);
const TICK: Duration = Duration::from_millis(100);
const END: Duration = Duration::from_secs(120);

/// Run the library entry `entry` on 3 robots under `fate`; `crash`: a robot
/// that goes silent at a time (the others are told it is lost 2 s later, as
/// the failure detector would); `inject`: extra inputs at given times.
fn run(
    entry: usize,
    mut fate: impl FnMut(&Copy) -> Fate,
    crash: Option<(usize, Duration)>,
    inject: &mut Inject<'_>,
) -> Run {
    let (kind, name, params) = LIBRARY[entry];
    let spec = ProbeSpec::library(kind, name, params, 3);
    let (g, s) = mission_text(&spec);
    let graph = bite_core::graph::load_str(&Arc::from("probe"), &g).expect("probe graph");
    let scenario = Scenario::load_str(&Arc::from("probe scenario"), &s).expect("probe scenario");
    let mission =
        bite_sim::prepare(&graph, &scenario, None, &bite_protocols::registry()).expect("mission");
    let n = mission.graph().roster().len();
    // The point under test: `a` (sync), `split` (allocate), `w` (terminate).
    let point = mission
        .graph()
        .find(match kind {
            bite_core::ids::Kind::Sync => "a",
            bite_core::ids::Kind::Allocate => "split",
            bite_core::ids::Kind::Terminate => "w",
        })
        .expect("the probe's point");
    let under_test = |key: &bite_core::ids::InstanceKey| key.behavior == point && key.kind == kind;
    let mut agents: Vec<Agent> = (0..n)
        .map(|i| Agent::new(mission.clone(), &scenario, RobotId(i as u32), 7).expect("agent"))
        .collect();
    let mut flight: Vec<(Time, usize, Envelope)> = Vec::new();
    let mut sent: Vec<Envelope> = Vec::new();
    let mut decisions: BTreeMap<usize, Vec<Decision>> = BTreeMap::new();
    let mut told_lost = false;
    let mut now = Time::ZERO;
    let alive = |i: usize, now: Time| crash.is_none_or(|(c, at)| c != i || now < Time::ZERO + at);
    while now <= Time::ZERO + END {
        // Messages due.
        let (due, later): (Vec<_>, Vec<_>) = flight.drain(..).partition(|(t, _, _)| *t <= now);
        flight = later;
        let mut work: Vec<(usize, Option<Envelope>)> =
            due.into_iter().map(|(_, to, e)| (to, Some(e))).collect();
        for i in 0..n {
            work.push((i, None));
        }
        for (i, msg) in work {
            if !alive(i, now) {
                continue;
            }
            match msg {
                Some(e) => agents[i].handle(now, Input::Message(&e)),
                None => {
                    if now.as_micros().is_multiple_of(TICK.as_micros() as u64) {
                        agents[i].handle(
                            now,
                            Input::Tick {
                                world: now,
                                sensed: None,
                            },
                        );
                    }
                    if agents[i].poll_timeout().is_some_and(|t| t <= now) {
                        agents[i].handle(now, Input::Timer);
                    }
                }
            }
            while let Some(o) = agents[i].poll() {
                match o {
                    AgentOutput::Send { to, envelope, .. } => {
                        let at_point = under_test(&envelope.instance);
                        let targets: Vec<usize> = match &to {
                            Recipients::One(r) => vec![r.index()],
                            Recipients::Team(m) => {
                                m.iter().map(|r| r.index()).filter(|r| *r != i).collect()
                            }
                        };
                        sent.push(envelope.clone());
                        for t in targets {
                            let c = Copy { from: i, at_point };
                            let at = now + LATENCY;
                            match if at_point { fate(&c) } else { Fate::Deliver } {
                                Fate::Deliver => flight.push((at, t, envelope.clone())),
                                Fate::Drop => {}
                                Fate::Duplicate => {
                                    flight.push((at, t, envelope.clone()));
                                    flight.push((at + LATENCY, t, envelope.clone()));
                                }
                                Fate::Hold(d) => flight.push((at + d, t, envelope.clone())),
                            }
                        }
                    }
                    AgentOutput::Event(Event::InteractionDecided {
                        instance,
                        outcome,
                        timed_out,
                        ..
                    }) if under_test(&instance) => {
                        decisions.entry(i).or_default().push(Decision {
                            outcome: serde_json::to_value(&outcome).expect("outcome"),
                            timed_out,
                            at: now,
                        });
                    }
                    _ => {}
                }
            }
        }
        inject(now, &mut agents, &sent);
        if let Some((c, at)) = crash
            && !told_lost
            && now >= Time::ZERO + at + Duration::from_secs(2)
        {
            told_lost = true;
            for (i, a) in agents.iter_mut().enumerate() {
                if i != c {
                    a.handle(now, Input::Lost(RobotId(c as u32)));
                }
            }
        }
        if (0..n).all(|i| !alive(i, now) || agents[i].kernel().is_finished()) {
            break;
        }
        now += Duration::from_millis(2);
    }
    let ids = ["s0", "s1", "s2", "c0", "c1", "c2"]
        .iter()
        .filter_map(|b| Some((b.to_string(), mission.graph().find(b)?.0)))
        .collect();
    Run {
        protocol: name,
        ids,
        completed: (0..n)
            .map(|i| !alive(i, now) || agents[i].kernel().is_finished())
            .collect(),
        decisions,
    }
}

fn no_inject() -> impl FnMut(Time, &mut Vec<Agent>, &[Envelope]) {
    |_, _, _| {}
}

impl Run {
    /// Every robot in `who` decided exactly once at the point; their
    /// outcomes, by robot.
    fn decided(&self, who: &[usize]) -> Vec<&Decision> {
        who.iter()
            .map(|r| {
                let d = self.decisions.get(r).unwrap_or_else(|| {
                    panic!(
                        "{}: r{r} never decided: {:?}",
                        self.protocol, self.decisions
                    )
                });
                assert_eq!(d.len(), 1, "{}: r{r} decided {d:?}", self.protocol);
                &d[0]
            })
            .collect()
    }

    /// The robots in `who` decided, alike, without a deadline; the outcome.
    fn agreed(&self, who: &[usize]) -> serde_json::Value {
        let d = self.decided(who);
        for x in &d {
            assert_eq!(x.outcome, d[0].outcome, "{}: {:?}", self.protocol, d);
            assert!(
                !x.timed_out,
                "{}: needed its deadline: {d:?}",
                self.protocol
            );
        }
        assert!(
            self.completed.iter().all(|c| *c),
            "{}: mission not completed",
            self.protocol
        );
        d[0].outcome.clone()
    }
}

/// Each script on every protocol of the library.
fn every_protocol(mut check: impl FnMut(usize)) {
    for entry in 0..LIBRARY.len() {
        check(entry);
    }
}

#[test]
fn the_library_has_every_protocol() {
    let names: Vec<&str> = LIBRARY.iter().map(|e| e.1).collect();
    let registry = bite_protocols::registry();
    // Protocols written in Rust; the graph-defined ones are tested against
    // their Rust twins (`graph_protocols.rs`).
    let all: Vec<&str> = registry
        .iter()
        .filter(|p| p.source().is_none())
        .map(|p| p.name())
        .collect();
    for p in &all {
        assert!(names.contains(p), "`{p}` has no scripted tests");
    }
    assert_eq!(all.len(), 16, "{all:?}");
}

/// Fault-free, every robot decides the same, with no deadline; the silent
/// rules and the deterministic protocols decide what they must.
#[test]
fn fault_free_every_member_decides_alike() {
    every_protocol(|e| {
        let r = run(e, |_| Fate::Deliver, None, &mut no_inject());
        let o = r.agreed(&[0, 1, 2]);
        match r.protocol {
            // The rule: the first successor; first-wins / local: no replacement.
            // The rule: the first successor whose precondition holds.
            "sync.by-rule" => assert_eq!(o["choice"], r.ids["s0"], "{o}"),
            "term.local" | "term.wait-all" | "term.majority" | "term.first-wins" => {
                assert_eq!(o["next"], serde_json::Value::Null, "{o}")
            }
            // SF2: members in id order, one per child here.
            "alloc.by-id" => assert_eq!(
                o["assignment"],
                serde_json::json!([[r.ids["c0"], [0]], [r.ids["c1"], [1]], [r.ids["c2"], [2]]]),
                "{o}"
            ),
            _ => {}
        }
    });
}

/// Every message at the point delivered twice: the same decision as
/// without duplicates, no deadline.
#[test]
fn duplicated_messages_change_nothing() {
    every_protocol(|e| {
        let clean = run(e, |_| Fate::Deliver, None, &mut no_inject()).agreed(&[0, 1, 2]);
        let dup = run(e, |_| Fate::Duplicate, None, &mut no_inject());
        assert_eq!(dup.agreed(&[0, 1, 2]), clean, "{}", dup.protocol);
    });
}

/// Any one message at the point lost (each in turn, for the first six):
/// every robot still decides exactly once, and the robots that decided
/// without a deadline agree (retries recover the message).
#[test]
fn one_lost_message_is_recovered_or_decided_by_the_deadline() {
    every_protocol(|e| {
        for k in 0..6 {
            let mut seen = 0usize;
            let r = run(
                e,
                |c| {
                    let lose = c.at_point && seen == k;
                    seen += usize::from(c.at_point);
                    if lose { Fate::Drop } else { Fate::Deliver }
                },
                None,
                &mut no_inject(),
            );
            let d = r.decided(&[0, 1, 2]);
            let normal: Vec<_> = d.iter().filter(|x| !x.timed_out).collect();
            for x in &normal {
                assert_eq!(
                    x.outcome, normal[0].outcome,
                    "{} lost #{k}: {d:?}",
                    r.protocol
                );
            }
            assert!(
                r.completed.iter().all(|c| *c),
                "{} lost #{k}: not completed",
                r.protocol
            );
        }
    });
}

/// Messages held back 30 s (past every deadline) arrive late: each robot
/// has decided once by then (by its deadline if it needed them), and the
/// late messages change no decision.
#[test]
fn late_messages_after_the_decision_change_nothing() {
    every_protocol(|e| {
        let r = run(
            e,
            |c| {
                if c.from == 2 {
                    Fate::Hold(Duration::from_secs(30))
                } else {
                    Fate::Deliver
                }
            },
            None,
            &mut no_inject(),
        );
        // Decided exactly once each (asserted by `decided`), completed.
        r.decided(&[0, 1, 2]);
        assert!(r.completed.iter().all(|c| *c), "{}", r.protocol);
    });
}

/// A member that goes silent before the point (crashed at 0.2 s, presumed
/// lost 2 s later): the others decide alike and complete; nothing waits for
/// ever.
#[test]
fn a_lost_member_is_not_waited_for() {
    every_protocol(|e| {
        let r = run(
            e,
            |_| Fate::Deliver,
            Some((2, Duration::from_millis(200))),
            &mut no_inject(),
        );
        let d = r.decided(&[0, 1]);
        if !d[0].timed_out && !d[1].timed_out {
            assert_eq!(d[0].outcome, d[1].outcome, "{}: {d:?}", r.protocol);
        }
        assert!(r.completed[0] && r.completed[1], "{}", r.protocol);
        assert!(
            d.iter()
                .all(|x| x.at < Time::ZERO + Duration::from_secs(60)),
            "{}: {d:?}",
            r.protocol
        );
    });
}

/// Foreign messages — a copy of every message re-sent as if from a robot
/// outside the roster, and an old message replayed after the decision —
/// are dropped: the decision is the fault-free one.
#[test]
fn foreign_and_replayed_messages_are_ignored() {
    every_protocol(|e| {
        let clean = run(e, |_| Fate::Deliver, None, &mut no_inject()).agreed(&[0, 1, 2]);
        let mut done = 0usize;
        let mut inject = |now: Time, agents: &mut Vec<Agent>, sent: &[Envelope]| {
            // Each new message, once, as from robot 9 (not on the roster).
            while done < sent.len() {
                let mut forged = sent[done].clone();
                forged.sender = RobotId(9);
                for a in agents.iter_mut() {
                    a.handle(now, Input::Message(&forged));
                }
                done += 1;
            }
        };
        let r = run(e, |_| Fate::Deliver, None, &mut inject);
        assert_eq!(r.agreed(&[0, 1, 2]), clean, "{}", r.protocol);
        // Everything replayed once more, 5 s after it was sent.
        let mut replay: Vec<(Time, Envelope)> = Vec::new();
        let mut seen = 0usize;
        let mut inject = |now: Time, agents: &mut Vec<Agent>, sent: &[Envelope]| {
            while seen < sent.len() {
                replay.push((now + Duration::from_secs(5), sent[seen].clone()));
                seen += 1;
            }
            for (_, env) in replay.iter().filter(|(t, _)| *t == now) {
                for a in agents.iter_mut() {
                    a.handle(now, Input::Message(env));
                }
            }
        };
        let r = run(e, |_| Fate::Deliver, None, &mut inject);
        assert_eq!(r.agreed(&[0, 1, 2]), clean, "{} (replayed)", r.protocol);
    });
}
