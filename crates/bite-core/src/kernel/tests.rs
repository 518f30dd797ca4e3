//! Unit tests for each step of Algorithm 1, on hand-built graphs, with a
//! tiny harness that delivers every message at once.

use super::*;
use crate::event::{DropReason, EndReason, Event, Via};
use crate::graph::load_str;
use crate::interaction::{Factory, Params, Protocol, Registry};
use std::collections::VecDeque;

/// A communicating test protocol: the first member to finish ends the
/// behavior for everyone (so that "the team ended it" can be tested here,
/// without the protocol library).
struct FirstWinsInst;
impl Interaction for FirstWinsInst {
    fn start(&mut self, _cx: &mut Cx<'_>) {}
    fn local_done(&mut self, cx: &mut Cx<'_>, why: crate::interaction::LocalEnd) {
        // Only a robot that sees the goal ends it for everyone.
        if why == crate::interaction::LocalEnd::Condition {
            cx.broadcast(Body::Release { next: None });
            cx.decide(Outcome::Terminate(None));
        }
    }
    fn on_message(&mut self, cx: &mut Cx<'_>, _from: RobotId, body: &Body) {
        if let Body::Release { next } = body {
            cx.decide(Outcome::Terminate(*next));
        }
    }
    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        cx.decide(Outcome::Terminate(None));
    }
}

/// A synchronization protocol that never decides by itself.
struct SilentInst;
impl Interaction for SilentInst {
    fn start(&mut self, _cx: &mut Cx<'_>) {}
    fn on_message(&mut self, _cx: &mut Cx<'_>, _f: RobotId, _b: &Body) {}
    fn on_deadline(&mut self, _cx: &mut Cx<'_>) {}
}

/// A communicating termination that only its deadline ends: a barrier
/// whose teammates' answers are all lost.
struct BarrierInst;
impl Interaction for BarrierInst {
    fn start(&mut self, _cx: &mut Cx<'_>) {}
    fn on_message(&mut self, _cx: &mut Cx<'_>, _f: RobotId, _b: &Body) {}
    fn on_deadline(&mut self, cx: &mut Cx<'_>) {
        cx.decide(Outcome::Terminate(None));
    }
}

/// A test protocol: its name, kind, whether it communicates, and its
/// instances.
struct TestProtocol {
    name: &'static str,
    kind: Kind,
    communicates: bool,
    make: fn() -> Box<dyn Interaction>,
}
impl Protocol for TestProtocol {
    fn name(&self) -> &'static str {
        self.name
    }
    fn kind(&self) -> Kind {
        self.kind
    }
    fn communicates(&self) -> bool {
        self.communicates
    }
    fn summary(&self) -> &'static str {
        "test"
    }
    fn configure(
        &self,
        _p: &Params,
        _: &mut crate::interaction::Setup<'_>,
    ) -> Result<Factory, crate::interaction::ConfigError> {
        let make = self.make;
        Ok(Arc::new(make))
    }
}

fn registry() -> Registry {
    let mut r = Registry::core();
    for (name, kind, communicates, make) in [
        (
            "term.test-first",
            Kind::Terminate,
            true,
            (|| Box::new(FirstWinsInst)) as fn() -> Box<dyn Interaction>,
        ),
        ("sync.test-never", Kind::Sync, false, || {
            Box::new(SilentInst)
        }),
        ("term.test-barrier", Kind::Terminate, true, || {
            Box::new(BarrierInst)
        }),
        ("alloc.test-never", Kind::Allocate, true, || {
            Box::new(SilentInst)
        }),
    ] {
        r.register(Arc::new(TestProtocol {
            name,
            kind,
            communicates,
            make,
        }));
    }
    r
}

struct Harness {
    kernels: Vec<Kernel>,
    events: Vec<(RobotId, Event)>,
    wire: VecDeque<(RobotId, Envelope)>,
    now: Time,
}

impl Harness {
    fn new(yaml: &str, robots: usize) -> Harness {
        let g = load_str(&Arc::from("test.yaml"), yaml).unwrap_or_else(|d| panic!("{d}"));
        let g = g.with_team_size(robots);
        let m = Arc::new(Mission::new(g, &registry()).unwrap_or_else(|d| panic!("{d}")));
        Harness {
            kernels: (0..robots as u32)
                .map(|r| Kernel::new(m.clone(), RobotId(r), u64::from(r)))
                .collect(),
            events: Vec::new(),
            wire: VecDeque::new(),
            now: Time::ZERO,
        }
    }
    fn id(&self, belief: &str) -> BeliefId {
        self.kernels[0]
            .beliefs()
            .symbols()
            .get(belief)
            .unwrap_or_else(|| panic!("no belief {belief}"))
    }
    /// Advance to `ms` and tick every robot with the same percepts.
    fn tick(&mut self, ms: u64, percepts: &[(&str, Value)]) {
        let p: Vec<(BeliefId, Value)> = percepts
            .iter()
            .map(|(n, v)| (self.id(n), v.clone()))
            .collect();
        self.now = Time::from_millis(ms);
        for i in 0..self.kernels.len() {
            self.kernels[i].tick(self.now, &p);
            self.drain(i);
        }
        self.pump();
    }
    /// Tick one robot only.
    fn tick_one(&mut self, r: usize, ms: u64, percepts: &[(&str, Value)]) {
        let p: Vec<(BeliefId, Value)> = percepts
            .iter()
            .map(|(n, v)| (self.id(n), v.clone()))
            .collect();
        self.now = Time::from_millis(ms);
        self.kernels[r].tick(self.now, &p);
        self.drain(r);
        self.pump();
    }
    fn drain(&mut self, i: usize) {
        while let Some(o) = self.kernels[i].poll_output() {
            match o {
                Output::Send(s) => match s.to {
                    Recipients::One(r) => self.wire.push_back((r, s.envelope)),
                    Recipients::Team(set) => {
                        for r in set.iter().filter(|r| r.index() != i) {
                            self.wire.push_back((r, s.envelope.clone()));
                        }
                    }
                },
                Output::Event(e) => self.events.push((RobotId(i as u32), e)),
            }
        }
    }
    fn pump(&mut self) {
        let mut delivered = 0;
        while let Some((to, env)) = self.wire.pop_front() {
            delivered += 1;
            assert!(delivered < 100_000, "message storm: last {env:?} to {to}");
            self.kernels[to.index()].message(self.now, env);
            self.drain(to.index());
        }
    }
    fn stack(&self, r: usize) -> Vec<&str> {
        let g = self.kernels[r].mission().graph();
        self.kernels[r]
            .stack()
            .iter()
            .map(|f| g.name_of(f.behavior))
            .collect()
    }
    fn events_of(&self, r: usize) -> Vec<&Event> {
        self.events
            .iter()
            .filter(|(x, _)| x.index() == r)
            .map(|(_, e)| e)
            .collect()
    }
    fn name(&self, b: BehaviorId) -> &str {
        self.kernels[0].mission().graph().name_of(b)
    }
    fn selected_via(&self, r: usize, behavior: &str) -> Vec<Via> {
        self.events_of(r)
            .into_iter()
            .filter_map(|e| match e {
                Event::Selected {
                    behavior: b, via, ..
                } if self.name(*b) == behavior => Some(*via),
                _ => None,
            })
            .collect()
    }
    fn terminated(&self, r: usize, behavior: &str) -> Vec<EndReason> {
        self.events_of(r)
            .into_iter()
            .filter_map(|e| match e {
                Event::Terminated {
                    behavior: b,
                    reason,
                    ..
                } if self.name(*b) == behavior => Some(*reason),
                _ => None,
            })
            .collect()
    }
}

const T: Value = Value::Bool(true);
const F: Value = Value::Bool(false);

#[test]
fn expansion_with_one_child_pushes_it_directly() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [mid] }
  mid: { team: true, children: [leaf] }
  leaf: { skill: idle, until: done }",
        2,
    );
    h.tick(0, &[]);
    for r in 0..2 {
        assert_eq!(h.stack(r), ["root", "mid", "leaf"]);
        assert_eq!(h.selected_via(r, "mid"), [Via::Expansion]);
        assert_eq!(h.selected_via(r, "root"), [Via::Start]);
        assert_eq!(h.kernels[r].leaf().map(|f| f.team), Some(TeamId::ROOT));
    }
}

#[test]
fn expansion_with_allocation_splits_the_team_and_links_both_ways() {
    let mut h = Harness::new(
        "start: walk
defaults: { terminate: term.local }
behaviors:
  walk: { team: true, children: [lead, left, right] }
  lead: { skill: lead, members: 1 }
  left: { skill: slot, members: 1 }
  right: { skill: slot }",
        4,
    );
    h.tick(0, &[]);
    assert_eq!(h.stack(0), ["walk", "lead"]);
    assert_eq!(h.stack(1), ["walk", "left"]);
    assert_eq!(h.stack(2), ["walk", "right"]);
    assert_eq!(
        h.stack(3),
        ["walk", "right"],
        "the unbounded child takes the rest"
    );
    assert_eq!(h.selected_via(2, "right"), [Via::Allocation]);
    // Every robot knows the whole split, both ways.
    let k = &h.kernels[0];
    let g = k.mission().graph().clone();
    let right = g.find("right").unwrap();
    let teams: Vec<TeamId> = k.org().teams_running(right).collect();
    assert_eq!(teams.len(), 1);
    let t = k.org().team(teams[0]).unwrap();
    assert_eq!(t.members.to_vec(), [RobotId(2), RobotId(3)]);
    assert_eq!(t.parent, Some(TeamId::ROOT));
    assert_eq!(k.org().behaviors_of(teams[0]).collect::<Vec<_>>(), [right]);
    assert_eq!(
        h.kernels[3].leaf().unwrap().team,
        teams[0],
        "same derived id everywhere"
    );
    k.org().check_invariants().unwrap();
}

#[test]
fn terminating_a_mid_stack_behavior_pops_its_descendants() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [phase1] }
  phase1: { team: true, children: [work], until: alarm, next: [phase2] }
  work: { skill: dig, until: dug }
  phase2: { skill: flee }",
        1,
    );
    h.tick(0, &[]);
    assert_eq!(h.stack(0), ["root", "phase1", "work"]);
    h.tick(100, &[("alarm", T)]);
    assert_eq!(h.stack(0), ["root", "phase2"]);
    let phase1 = h.kernels[0].mission().graph().find("phase1").unwrap();
    assert_eq!(h.terminated(0, "work"), [EndReason::Ancestor(phase1)]);
    assert_eq!(h.terminated(0, "phase1"), [EndReason::Until]);
    // The condition that fired is reported with the beliefs it read.
    assert!(h.events_of(0).iter().any(|e| matches!(e,
        Event::ConditionHeld { field: "until", beliefs, .. }
            if beliefs == &vec![(Arc::from("alarm"), Some(T))])));
}

#[test]
fn the_end_of_a_chain_terminates_the_parent_and_then_the_mission() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { skill: x, until: a_done, next: [b] }
  b: { skill: y, until: b_done }",
        1,
    );
    h.tick(0, &[]);
    h.tick(100, &[("a_done", T)]);
    assert_eq!(h.stack(0), ["root", "b"]);
    assert_eq!(h.selected_via(0, "b"), [Via::Sequence]);
    h.tick(200, &[("b_done", T)]);
    assert!(h.stack(0).is_empty());
    assert_eq!(h.terminated(0, "root"), [EndReason::ChainEnded]);
    assert!(h.kernels[0].is_finished());
    assert!(h.events_of(0).contains(&&Event::MissionCompleted));
}

#[test]
fn a_single_enabled_successor_is_taken_without_a_protocol() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local, sync: sync.test-never }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, until: a_done, next: [b, c] }
  b: { pre: want_b, until: never }
  c: { pre: want_c, until: never }",
        2,
    );
    // `b` and `c` are not team behaviors: `a` is not a synchronization
    // point, so the choice is local (first enabled in graph order).
    h.tick(0, &[]);
    h.tick(100, &[("a_done", T), ("want_c", T)]);
    for r in 0..2 {
        assert_eq!(h.stack(r), ["root", "c"]);
        assert_eq!(h.selected_via(r, "c"), [Via::Sequence]);
    }
}

#[test]
fn several_enabled_successors_at_a_sync_point_are_decided_by_the_protocol() {
    let yaml = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, until: a_done, next: [b, c, d] }
  b: { team: true, pre: want_b, until: never }
  c: { team: true, pre: want_c, until: never }
  d: { team: true, pre: want_d, until: never }";
    let mut h = Harness::new(yaml, 3);
    h.tick(0, &[]);
    h.tick(100, &[("a_done", T), ("want_c", T), ("want_d", T)]);
    for r in 0..3 {
        assert_eq!(
            h.stack(r),
            ["root", "c"],
            "sync.by-rule: first enabled in graph order"
        );
        assert_eq!(h.selected_via(r, "c"), [Via::Decision]);
    }
    // None enabled: the chain ends and the parent terminates.
    let mut h = Harness::new(yaml, 1);
    h.tick(0, &[]);
    h.tick(100, &[("a_done", T)]);
    assert!(h.kernels[0].is_finished());
}

#[test]
fn a_sequential_cycle_repeats_a_behavior_by_choice() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [patrol] }
  patrol: { team: true, skill: go, pre: 'runs < 3', until: lap_done, next: [patrol, home] }
  home: { team: true, pre: 'runs(patrol) >= 3', until: at_home }",
        1,
    );
    // `patrol` may follow itself; `runs(patrol)` counts its executions.
    h.tick(0, &[]);
    let mut lap = 0;
    while h.stack(0) == ["root", "patrol"] && lap < 10 {
        lap += 1;
        h.tick(100 * lap, &[("lap_done", T)]);
        h.tick(100 * lap + 50, &[("lap_done", F)]);
    }
    assert_eq!(h.stack(0), ["root", "home"]);
    assert_eq!(
        h.selected_via(0, "patrol").len(),
        3,
        "patrol ran three times"
    );
    let epochs: Vec<u32> = h
        .events_of(0)
        .iter()
        .filter_map(|e| match e {
            Event::Selected {
                behavior, epoch, ..
            } if h.name(*behavior) == "patrol" => Some(*epoch),
            _ => None,
        })
        .collect();
    assert_eq!(epochs, [1, 2, 3], "each repetition is a new epoch");
}

#[test]
fn a_new_behavior_runs_for_at_least_one_input() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { until: go, next: [b] }
  b: { until: go }",
        1,
    );
    h.tick(0, &[]);
    h.tick(100, &[("go", T)]);
    assert_eq!(
        h.stack(0),
        ["root", "b"],
        "b is not ended by the input that selected it"
    );
    h.tick(200, &[]);
    assert!(h.kernels[0].is_finished(), "but by the next one");
}

#[test]
fn the_team_can_end_a_behavior_a_member_is_still_running() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [search] }
  search: { team: true, skill: look, until: found, next: [report], terminate: term.test-first }
  report: { team: true, until: never }",
        3,
    );
    h.tick(0, &[]);
    // Only robot 1 sees the target.
    h.tick_one(1, 100, &[("found", T)]);
    for r in 0..3 {
        assert_eq!(h.stack(r), ["root", "report"], "robot {r}");
    }
    assert_eq!(h.terminated(1, "search"), [EndReason::Until]);
    assert_eq!(h.terminated(0, "search"), [EndReason::Team]);
    assert_eq!(h.terminated(2, "search"), [EndReason::Team]);
}

/// `a`, then `b` or `c` by a synchronization that never decides by
/// itself (deadline 2 s).
const A_NEVER_2S: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, until: a_done, next: [b, c], sync: { protocol: sync.test-never, deadline: 2s } }
  b: { team: true, until: never }
  c: { team: true, until: never }";

#[test]
fn a_protocol_that_misses_its_deadline_is_replaced_by_the_silent_rule() {
    let mut h = Harness::new(A_NEVER_2S, 2);
    h.tick(0, &[]);
    h.tick(100, &[("a_done", T)]);
    // Each hears the other (one never heard would be called first: see
    // `a_robot_calls_the_teammates_it_never_heard_when_its_deadline_falls`).
    h.heartbeats();
    assert_eq!(h.stack(0), ["root"], "waiting for the decision");
    assert!(h.kernels[0].is_interacting());
    assert_eq!(h.kernels[0].poll_timeout(), Some(Time::from_millis(2100)));
    h.now = Time::from_millis(2100);
    h.kernels[0].timer(h.now);
    h.drain(0);
    assert_eq!(h.stack(0), ["root", "b"]);
    assert!(h.events_of(0).iter().any(|e| matches!(
        e,
        Event::InteractionTimedOut {
            protocol_decided: false,
            ..
        }
    )));
    assert!(h.events_of(0).iter().any(|e| matches!(
        e,
        Event::InteractionDecided {
            timed_out: true,
            ..
        }
    )));
    assert_eq!(h.kernels[0].stats().timeouts, 1);
}

/// An instance whose coordinator changes just before its deadline does
/// not reach the deadline within a retry from the change: the new
/// coordinator has had no time to gather the team (a member's deadline
/// fell 0.01 s after its leader, heard at work until then, left and the
/// next took over: docs/reliability.md, "A deadline just after the leader
/// changed").
#[test]
fn a_deadline_waits_a_retry_for_a_new_coordinator() {
    let mut h = Harness::new(A_NEVER_2S, 3);
    h.tick(0, &[]);
    h.tick_one(2, 100, &[("a_done", T)]);
    assert_eq!(h.stack(2), ["root"], "robot 2 waits at the point");
    assert_eq!(h.kernels[2].poll_timeout(), Some(Time::from_millis(2100)));
    // Robot 1 leaving changes nothing: robot 0 still coordinates.
    h.kernels[2].member_lost(Time::from_millis(2000), RobotId(1));
    assert_eq!(h.kernels[2].poll_timeout(), Some(Time::from_millis(2100)));
    // Robot 0, the coordinator, leaves 10 ms before the deadline.
    h.kernels[2].member_lost(Time::from_millis(2090), RobotId(0));
    let due = h.kernels[2].poll_timeout().expect("still waiting");
    assert!(due > Time::from_millis(2100), "deadline kept at {due:?}");
    h.kernels[2].timer(Time::from_millis(2100));
    h.drain(2);
    assert_eq!(h.kernels[2].stats().timeouts, 0, "not at the old deadline");
    h.kernels[2].timer(due);
    h.drain(2);
    assert_eq!(
        h.kernels[2].stats().timeouts,
        1,
        "a retry later, it decides"
    );
}

#[test]
fn a_behavior_without_enabled_children_waits_for_one() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [gated] }
  gated: { pre: door_open, until: never }",
        1,
    );
    h.tick(0, &[]);
    assert_eq!(h.stack(0), ["root"]);
    assert_eq!(h.kernels[0].phase_name(), "waiting-for-child");
    h.tick(100, &[]);
    h.tick(200, &[("door_open", T)]);
    assert_eq!(h.stack(0), ["root", "gated"]);
    let waits = h
        .events_of(0)
        .iter()
        .filter(|e| matches!(e, Event::WaitingForChild { .. }))
        .count();
    assert_eq!(waits, 1, "reported once, not every tick");
}

#[test]
fn a_member_left_without_a_child_idles_until_the_parent_ends() {
    let yaml = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [split], next: [after] }
  split: { team: true, children: [x, y], until: over, next: [split], terminate: TERM }
  x: { members: 1, until: never }
  y: { members: 1, until: never }
  after: { until: never }";
    // A silent termination protocol: nobody will tell the idle robot when
    // the others are done, so it ends its empty part at its next tick — at
    // most once per tick around the sequential cycle back to `split`.
    let mut h = Harness::new(&yaml.replace("TERM", "term.local"), 3);
    h.tick(0, &[]);
    assert_eq!(h.stack(0), ["root", "split", "x"]);
    assert_eq!(h.stack(1), ["root", "split", "y"]);
    assert_eq!(h.stack(2), ["root", "split"]);
    assert_eq!(h.kernels[2].phase_name(), "idle");
    assert!(
        h.events_of(2)
            .iter()
            .any(|e| matches!(e, Event::Unassigned { .. }))
    );
    for t in 1..=10 {
        h.tick(t * 100, &[]);
    }
    assert_eq!(
        h.selected_via(2, "split").len(),
        11,
        "once per tick, never a spin"
    );

    // A communicating protocol is told at once that the idle robot has no
    // part; here the first member to see the goal ends it for everyone,
    // the idle robot included.
    let mut h = Harness::new(&yaml.replace("TERM", "term.test-first"), 3);
    h.tick(0, &[]);
    h.tick(100, &[]);
    assert_eq!(
        h.stack(2),
        ["root", "split"],
        "idling is not seeing the goal"
    );
    h.tick_one(0, 200, &[("over", T)]);
    assert_eq!(h.terminated(2, "split"), [EndReason::Team]);
    assert_eq!(h.terminated(1, "split"), [EndReason::Team]);
}

/// Two team behaviors in a loop under the root, for the message tests.
const S_THEN_T: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [s], }
  s: { team: true, until: found, terminate: term.test-first, next: [t] }
  t: { team: true, until: t_done, terminate: term.test-first, next: [s] }";

/// An `Ack` from robot 1 for an instance of round 0.
fn ack_from_r1(seq: u64, team: TeamId, behavior: BehaviorId, kind: Kind, epoch: u32) -> Envelope {
    Envelope {
        instance: InstanceKey {
            team,
            behavior,
            kind,
            epoch,
            round: 0,
        },
        sender: RobotId(1),
        seq,
        body: Body::Ack,
    }
}

#[test]
fn messages_are_deduplicated_and_stale_or_foreign_ones_dropped() {
    let mut h = Harness::new(S_THEN_T, 2);
    h.tick(0, &[]);
    let g = h.kernels[0].mission().graph().clone();
    let s = g.find("s").unwrap();
    let t = g.find("t").unwrap();
    let env = |seq: u64, behavior: BehaviorId, kind: Kind, epoch: u32| {
        ack_from_r1(seq, TeamId::ROOT, behavior, kind, epoch)
    };
    let k = &mut h.kernels[0];
    // A message for an instance not reached yet is buffered...
    k.message(Time(1), env(1, t, Kind::Terminate, 1));
    assert_eq!(k.stats().buffered, 1);
    // ...a duplicate is dropped...
    k.message(Time(2), env(1, t, Kind::Terminate, 1));
    // ...so is a message naming a point that does not exist (`t` has a
    // single successor: it is not a synchronization point)...
    k.message(Time(3), env(2, t, Kind::Sync, 1));
    // ...and one for a team the robot is not in, and one from itself.
    let mut foreign = env(3, s, Kind::Terminate, 1);
    foreign.instance.team = TeamId(42);
    k.message(Time(4), foreign);
    let mut own = env(4, s, Kind::Terminate, 1);
    own.sender = RobotId(0);
    k.message(Time(5), own);
    let dropped = &k.stats().dropped;
    assert_eq!(dropped.get(&DropReason::Duplicate), Some(&1));
    assert_eq!(dropped.get(&DropReason::Malformed), Some(&1));
    assert_eq!(dropped.get(&DropReason::OwnMessage), Some(&1));
    // TeamId(42) is unknown, not known dead: buffered as a possible future team.
    assert_eq!(k.stats().buffered, 2);
    // Once `s` #1 is decided and forgotten, its outcome still answers late
    // teammates (received, not dropped).
    h.tick(100, &[("found", T)]);
    h.tick(2_000, &[]);
    let k = &mut h.kernels[0];
    let received = k.stats().received;
    k.message(Time::from_millis(2_050), env(10, s, Kind::Terminate, 1));
    assert_eq!(k.stats().received, received + 1);
    assert_eq!(k.stats().dropped.get(&DropReason::Stale), None);
    // Ids from beyond the roster are rejected before anything else.
    let mut stranger = env(11, s, Kind::Terminate, 1);
    stranger.sender = RobotId(99);
    k.message(Time::from_millis(2_060), stranger);
    assert_eq!(k.stats().dropped.get(&DropReason::UnknownSender), Some(&1));
}

/// Buffered messages the kernel forgets are counted by why: stale (their
/// execution is over) or past their time to live (`Limits::pending_ttl`),
/// not all as a full buffer.
#[test]
fn forgotten_buffered_messages_are_counted_stale_or_expired() {
    let mut h = Harness::new(S_THEN_T, 2);
    h.tick(0, &[]);
    let t = h.kernels[0].mission().graph().find("t").unwrap();
    let env = |seq: u64, team: TeamId| ack_from_r1(seq, team, t, Kind::Terminate, 1);
    let k = &mut h.kernels[0];
    // One for `t` #1, not reached yet; one for a team not known yet.
    k.message(Time(1), env(1, TeamId::ROOT));
    k.message(Time(2), env(2, TeamId(42)));
    assert_eq!(k.stats().buffered, 2);
    // `t` #1 is over (as if this robot went past it with its team): its
    // message is stale.
    k.closed.insert((TeamId::ROOT, t, Kind::Terminate), (1, 0));
    k.gc();
    assert_eq!(k.stats().dropped.get(&DropReason::Stale), Some(&1));
    assert_eq!(k.stats().dropped.get(&DropReason::BufferOverflow), None);
    // The other waits until its time to live is past.
    k.now = Time(2) + k.limits.pending_ttl;
    k.gc();
    assert_eq!(k.stats().dropped.get(&DropReason::Stale), Some(&1));
    assert_eq!(k.stats().dropped.get(&DropReason::BufferOverflow), Some(&1));
}

#[test]
fn kernels_are_deterministic() {
    let yaml = "start: root
defaults: { terminate: term.test-first }
behaviors:
  root: { team: true, children: [split], until: all_done }
  split: { team: true, children: [a, b, c], until: step }
  a: { team: true, until: step }
  b: { team: true, until: step }
  c: { team: true, until: step }";
    let run = || {
        let mut h = Harness::new(yaml, 5);
        for i in 0..20 {
            h.tick(i * 100, &[("step", Value::Bool(i % 3 == 0))]);
        }
        h.tick(3000, &[("all_done", T)]);
        format!("{:?}", h.events)
    };
    assert_eq!(run(), run());
}

#[test]
fn a_timed_precondition_is_rechecked_while_waiting_for_a_child() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [later] }
  later: { pre: 'age(flag) > 2', until: never }",
        1,
    );
    h.tick(0, &[("flag", T)]);
    assert_eq!(h.stack(0), ["root"]);
    for t in 1..=25 {
        h.tick(t * 100, &[]);
    }
    assert_eq!(
        h.stack(0),
        ["root", "later"],
        "selected once the flag is 2 s old"
    );
}

#[test]
fn a_forged_replacement_cannot_push_an_ancestor() {
    let mut h = Harness::new(
        "start: mission
defaults: { terminate: term.test-first }
behaviors:
  mission: { team: true, children: [work] }
  work: { team: true, until: done, next: [more] }
  more: { team: true, until: never }",
        2,
    );
    h.tick(0, &[]);
    let g = h.kernels[1].mission().graph().clone();
    let (mission, work) = (g.find("mission").unwrap(), g.find("work").unwrap());
    // The leader "releases" `work` naming the root as the next behavior.
    for seq in 1..=3 {
        h.kernels[1].message(
            Time::from_millis(100 + seq),
            Envelope {
                instance: first_termination(work),
                sender: RobotId(0),
                seq,
                body: Body::Release {
                    next: Some(mission),
                },
            },
        );
        h.drain(1);
    }
    assert_eq!(
        h.stack(1),
        ["mission", "more"],
        "the stack never holds `mission` twice"
    );
    assert!(
        h.events_of(1)
            .iter()
            .any(|e| matches!(e, Event::ProtocolViolation { .. }))
    );
}

#[test]
fn memory_stays_bounded_over_a_long_mission() {
    // A round that splits the team again and again, forever.
    let mut h = Harness::new(
        "start: mission
defaults: { terminate: term.test-first }
behaviors:
  mission: { team: true, children: [round] }
  round: { team: true, children: [a, b], until: step, next: [round] }
  a: { team: true, members: 1, until: never }
  b: { team: true, until: never }",
        3,
    );
    let mut sizes = Vec::new();
    // 400 simulated seconds, sampled every 100 s: after the first 200 s
    // (the duplicate filter remembers 120 s) nothing may grow any more.
    for i in 0..4000u64 {
        h.tick(i * 100, &[("step", Value::Bool(i % 2 == 0))]);
        if i % 1000 == 999 {
            sizes.push(h.kernels[0].footprint());
        }
    }
    let rounds = h.selected_via(0, "round").len();
    assert!(rounds > 1500, "{rounds} rounds");
    let last = sizes[sizes.len() - 1];
    assert_eq!(
        sizes[2], last,
        "tables do not grow with the number of rounds: {sizes:?}"
    );
    assert!(
        last.closed < 10 && last.teams < 10 && last.instances < 400,
        "{last:?}"
    );
}

/// Two robots split between `x` and `y` under `split`, which ends (at
/// 100 ms, "over") for `after`.
const SPLIT_THEN_AFTER: &str = "start: root
defaults: { terminate: term.test-first }
behaviors:
  root: { team: true, children: [split] }
  split: { team: true, children: [x, y], until: over, next: [after] }
  x: { team: true, members: 1, until: never }
  y: { team: true, members: 1, until: never }
  after: { team: true, until: never }";

impl Harness {
    /// [`SPLIT_THEN_AFTER`] run until both robots run `after`.
    fn split_then_after(during: impl FnOnce(&Harness)) -> Harness {
        let mut h = Harness::new(SPLIT_THEN_AFTER, 2);
        h.tick(0, &[]);
        during(&h);
        h.tick(100, &[("over", T)]);
        h.tick(200, &[]);
        assert_eq!(h.stack(0), ["root", "after"]);
        h
    }
}

#[test]
fn messages_for_a_dissolved_subteam_are_stale() {
    let mut y_team = TeamId::ROOT;
    let mut h = Harness::split_then_after(|h| {
        let g = h.kernels[0].mission().graph().clone();
        // Robot 0 runs x; robot 1 runs y in its own subteam.
        y_team = TeamId::derive(
            TeamId::ROOT,
            g.find("split").unwrap(),
            (1, 0),
            1,
            crate::org::MemberSet::from_iter(2, [RobotId(1)]).fingerprint(),
        );
        assert!(h.kernels[0].org().team(y_team).is_some());
    });
    let y = h.kernels[0].mission().graph().find("y").unwrap();
    assert!(h.kernels[0].org().is_dead(y_team), "dissolved with `split`");
    // A late message in y's subteam (which robot 0 never joined) is stale.
    h.kernels[0].message(
        Time::from_millis(250),
        Envelope {
            instance: InstanceKey {
                team: y_team,
                behavior: y,
                kind: Kind::Terminate,
                epoch: 1,
                round: 0,
            },
            sender: RobotId(1),
            seq: 99,
            body: Body::Done,
        },
    );
    assert_eq!(
        h.kernels[0].stats().dropped.get(&DropReason::Stale),
        Some(&1)
    );
}

/// What robot `k` sends in answer to robot 1's message `body` (number
/// `seq`) for instance `key`, heard at `ms`.
fn answers_to(k: &mut Kernel, key: InstanceKey, ms: u64, seq: u64, body: Body) -> Vec<Body> {
    k.message(
        Time::from_millis(ms),
        Envelope {
            instance: key,
            sender: RobotId(1),
            seq,
            body,
        },
    );
    std::iter::from_fn(|| k.poll_output())
        .filter_map(|o| match o {
            Output::Send(s) => Some(s.envelope.body),
            Output::Event(_) => None,
        })
        .collect()
}

/// A robot that has left a behavior answers a teammate's re-allocation of
/// it with `Done`, but answers neither a `Done` nor a notice: two robots
/// that had both left it answered each other's `Done` for ever
/// (docs/reliability.md, "Two robots answering each other").
#[test]
fn a_robot_done_with_a_behavior_answers_a_call_but_not_an_answer() {
    let mut h = Harness::split_then_after(|_| {});
    let split = h.kernels[0].mission().graph().find("split").unwrap();
    let k = &mut h.kernels[0];
    while k.poll_output().is_some() {}
    let round1 = InstanceKey {
        team: TeamId::ROOT,
        behavior: split,
        kind: Kind::Allocate,
        epoch: 1,
        round: 1,
    };
    let answers = |k: &mut Kernel, seq: u64, body: Body| answers_to(k, round1, 250, seq, body);
    assert_eq!(
        answers(k, 100, Body::Reallocate { lost: vec![] }),
        [Body::Done]
    );
    assert_eq!(answers(k, 101, Body::Done), []);
    let notice = Body::Missed {
        choice: None,
        children: vec![],
        members: vec![],
    };
    assert_eq!(answers(k, 102, notice), []);
}

/// A teammate's `Query` about the first execution of the root team's
/// point `kind` of `behavior`, sent to a kernel at `ms` with sequence
/// number `seq`: what the kernel answers (its outputs so far drained).
fn query_of_root_point(
    behavior: &'static str,
    kind: Kind,
) -> impl Fn(&mut Kernel, u64, u64) -> Vec<Body> {
    move |k: &mut Kernel, ms: u64, seq: u64| {
        let key = InstanceKey {
            team: TeamId::ROOT,
            behavior: k.mission().graph().find(behavior).unwrap(),
            kind,
            epoch: 1,
            round: 0,
        };
        while k.poll_output().is_some() {}
        answers_to(k, key, ms, seq, Body::Query)
    }
}

/// A robot that left an execution before its synchronization (the
/// behavior above it ended) answers a teammate's question about that
/// synchronization with `Done`, and one still running it keeps the
/// question for when it gets there. Kept for later by a robot that had
/// left, the question waited for ever, and the teammate for its deadline
/// (docs/reliability.md, "A member that found its coordinator gone at the
/// point", property seed 2677).
#[test]
fn a_robot_that_left_an_execution_answers_a_question_about_its_synchronization() {
    const P_A: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { team: true, children: [a], until: p_done }
  a: { team: true, skill: w, until: a_done, next: [b, c], sync: sync.test-never }
  b: { team: true, skill: w }
  c: { team: true, skill: w }";
    let mut h = Harness::new(P_A, 2);
    h.tick(0, &[("a_done", F), ("p_done", F)]);
    let answers = query_of_root_point("a", Kind::Sync);
    // Still in `a`: the question waits for its synchronization.
    assert_eq!(h.stack(0), ["root", "p", "a"]);
    assert_eq!(answers(&mut h.kernels[0], 50, 100), []);
    // `p` ends by its own condition: r0 leaves `a` before its point.
    h.tick_one(0, 100, &[("p_done", T)]);
    assert!(!h.stack(0).contains(&"a"), "{:?}", h.stack(0));
    assert_eq!(answers(&mut h.kernels[0], 150, 101), [Body::Done]);
}

/// The same for an allocation: a robot whose count of a behavior's runs
/// is past an execution it does not run (a teammate's word raised it: it
/// converged onto a teammate further on, past that execution) answers a
/// teammate's question about the execution's allocation with `Done`. It
/// kept the question for a point it would never reach, and the teammate,
/// which took it for the coordinator, waited out its deadline (property
/// seeds 3251 and 3973, docs/reliability.md, "A coordinator that went past
/// the allocation"). Before its count got there, it keeps the question.
#[test]
fn a_robot_counted_past_an_execution_answers_a_question_about_its_allocation() {
    const S_A: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [s] }
  s: { team: true, skill: w, until: s_done, next: [a] }
  a: { team: true, children: [x, y] }
  x: { team: true, skill: w }
  y: { team: true, skill: w }";
    let mut h = Harness::new(S_A, 2);
    h.tick(0, &[("s_done", F)]);
    let a = h.kernels[0].mission().graph().find("a").unwrap();
    let answers = query_of_root_point("a", Kind::Allocate);
    // On its way to `a`#1: the question waits for the allocation.
    assert_eq!(h.stack(0), ["root", "s"]);
    assert_eq!(answers(&mut h.kernels[0], 50, 100), []);
    // Its count of `a` is raised past #1 (as `converge` and `count_past`
    // do): its next `a` is #2, and it will never reach #1's point.
    h.kernels[0].org.runs_at_least(TeamId::ROOT, a, 1);
    assert_eq!(h.stack(0), ["root", "s"]);
    assert_eq!(answers(&mut h.kernels[0], 100, 101), [Body::Done]);
}

impl Harness {
    /// One round of heartbeats as the runtimes send them: each robot's
    /// position to its `beacon_audience`.
    fn heartbeats(&mut self) {
        let sent: Vec<(Position, MemberSet)> = self
            .kernels
            .iter()
            .map(|k| {
                let (pos, to) = (k.position(), k.beacon_audience());
                // The runtimes' one call for both says the same.
                let both = k.beacon();
                assert_eq!(both.is_none(), to.is_empty());
                if let Some((a, p)) = both {
                    assert_eq!((&a, &p), (&to, &pos));
                }
                (pos, to)
            })
            .collect();
        for (j, (p, to)) in sent.iter().enumerate() {
            for r in to.iter() {
                self.kernels[r.index()].peer(self.now, RobotId(j as u32), p);
            }
        }
        for i in 0..self.kernels.len() {
            self.drain(i);
        }
        self.pump();
    }

    /// Every robot hears every other's heartbeat (its position).
    fn beacons(&mut self) {
        let positions: Vec<Position> = self.kernels.iter().map(Kernel::position).collect();
        for (i, k) in self.kernels.iter_mut().enumerate() {
            for (j, p) in positions.iter().enumerate() {
                if i != j {
                    k.peer(self.now, RobotId(j as u32), p);
                }
            }
        }
        for i in 0..self.kernels.len() {
            self.drain(i);
        }
        self.pump();
    }
}

const COURSE: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, until: a_done, next: [b] }
  b: { team: true, until: never }";

fn version2(h: &Harness, text: &str) -> Arc<Mission> {
    let g = load_str(&Arc::from("v2.yaml"), text)
        .unwrap_or_else(|d| panic!("{d}"))
        .with_team_size(h.kernels.len());
    let g = g
        .aligned_to(h.kernels[0].mission().graph())
        .unwrap_or_else(|e| panic!("{e}"));
    Arc::new(Mission::new(g, &registry()).unwrap_or_else(|d| panic!("{d}")))
}

#[test]
fn a_team_switches_to_a_new_version_together_at_a_safe_point() {
    let mut h = Harness::new(COURSE, 2);
    h.tick(0, &[]);
    let v2 = version2(
        &h,
        &COURSE.replace("next: [b]", "next: [c]").replace(
            "  b: { team: true, until: never }",
            "  c: { team: true, until: never }",
        ),
    );
    for k in &mut h.kernels {
        k.offer_change(Time::from_millis(50), 1, v2.clone())
            .expect("offered");
        assert_eq!(k.pending_version(), Some(1));
    }
    // The member reaches the boundary first: it holds for its leader.
    h.tick_one(1, 100, &[("a_done", T)]);
    assert_eq!(h.stack(1), ["root"], "r1 holds at the safe point");
    assert_eq!(h.kernels[1].version(), 0);
    // Heartbeats: the leader learns that every member holds version 1.
    h.beacons();
    h.tick_one(0, 200, &[("a_done", T)]);
    assert_eq!(h.kernels[0].version(), 1);
    assert_eq!(h.stack(0), ["root", "c"]);
    // The member hears the leader's decision and follows.
    h.beacons();
    h.tick_one(1, 300, &[("a_done", T)]);
    assert_eq!(h.kernels[1].version(), 1);
    assert_eq!(h.stack(1), ["root", "c"]);
    for r in 0..2 {
        let changed: Vec<_> = h
            .events_of(r)
            .into_iter()
            .filter_map(|e| match e {
                Event::MissionChanged { version, after, .. } => Some((*version, *after)),
                _ => None,
            })
            .collect();
        let a = h.kernels[0].mission().graph().find("a").unwrap();
        assert_eq!(
            changed,
            [(
                1,
                Some(crate::event::FrameRef {
                    behavior: a,
                    epoch: 1
                })
            )]
        );
    }
    // The same version again, or one not numbered like the running one,
    // is refused with the reason.
    let again = h.kernels[0].offer_change(Time::from_millis(400), 1, v2.clone());
    assert!(again.unwrap_err().0.contains("not newer"));
    let stranger = load_str(
        &Arc::from("x.yaml"),
        "start: z\nbehaviors:\n  z: { until: never }",
    )
    .unwrap_or_else(|d| panic!("{d}"))
    .with_team_size(2);
    let stranger = Arc::new(Mission::new(stranger, &registry()).unwrap_or_else(|d| panic!("{d}")));
    let e = h.kernels[0].offer_change(Time::from_millis(400), 2, stranger);
    assert!(e.unwrap_err().0.contains("not numbered like"));
}

#[test]
fn a_team_goes_on_in_the_running_version_until_every_member_holds_the_new_one() {
    let mut h = Harness::new(COURSE, 2);
    h.tick(0, &[]);
    let v2 = version2(&h, &COURSE.replace("until: never", "until: b_done"));
    // Only the leader holds version 1: it goes on in version 0 and says so.
    h.kernels[0]
        .offer_change(Time::from_millis(50), 1, v2)
        .expect("offered");
    h.beacons();
    h.tick(100, &[("a_done", T)]);
    for r in 0..2 {
        assert_eq!(h.stack(r), ["root", "b"], "r{r}");
        assert_eq!(h.kernels[r].version(), 0);
    }
    assert!(h.events_of(0).iter().any(|e| matches!(
        e,
        Event::MissionChangeDeferred {
            timed_out: false,
            ..
        }
    )));
    assert_eq!(h.kernels[0].pending_version(), Some(1), "still pending");
}

/// `a`, then a sync point that never decides: robots that end `a` wait
/// there while the others still run it.
const A_THEN_WAIT: &str = "start: root
defaults: { terminate: term.local, sync: { protocol: sync.test-never, deadline: 60s } }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, until: a_done, next: [b, c] }
  b: { team: true, until: never }
  c: { team: true, until: never }";

/// A leader's report of who departed a frame it ended lists the leader
/// itself, so that the members still running the frame keep that report as
/// it is: one bit set shared by the team instead of a roster-sized copy per
/// member (at 100,000 robots those copies were 1.25 GB).
#[test]
fn members_keep_the_leaders_departure_report_itself() {
    let mut h = Harness::new(A_THEN_WAIT, 40);
    h.tick(0, &[]);
    h.tick(100, &[]);
    // Robots 0 (the leader) to 7 end `a` and wait at its sync point.
    for r in 0..8 {
        h.tick_one(r, 200, &[("a_done", T)]);
    }
    let a = h.kernels[0].mission().graph().find("a").expect("a");
    // The leader hears who ended, then tells the team.
    h.heartbeats();
    h.heartbeats();
    let pos = h.kernels[0].position();
    let ended = pos.frames.last().expect("a frame");
    assert_eq!(ended.id.behavior, a);
    assert_ne!(ended.state, FrameState::Running);
    let report = ended.departed.as_ref().expect("a report");
    assert_eq!(
        report.iter().map(|r| r.0).collect::<Vec<_>>(),
        (0..8).collect::<Vec<_>>(),
        "the leader lists itself with the members that ended"
    );
    // Members still running `a` know the same, in one shared set.
    let known = |r: usize| {
        let f = h.kernels[r].stack().last().expect("a frame");
        assert_eq!(f.behavior, a);
        f.departed.clone().expect("departures learnt")
    };
    let (first, second) = (known(20), known(39));
    assert_eq!(
        first.iter().map(|r| r.0).collect::<Vec<_>>(),
        (0..8).collect::<Vec<_>>()
    );
    assert!(
        first.shares_bits(&second),
        "members hold the leader's report, not copies"
    );
}

#[test]
fn a_silent_protocol_names_itself_when_sent_a_message() {
    let mut h = Harness::new(COURSE, 2);
    h.tick(0, &[]);
    assert_eq!(h.stack(1), ["root", "a"]);
    let a = h.kernels[1].mission().graph().find("a").expect("a");
    h.kernels[1].message(
        Time::from_millis(50),
        Envelope {
            instance: first_termination(a),
            sender: RobotId(0),
            seq: 1,
            body: Body::Release { next: None },
        },
    );
    h.drain(1);
    let what: Vec<&str> = h
        .events_of(1)
        .into_iter()
        .filter_map(|e| match e {
            Event::ProtocolViolation { what, .. } => Some(what.as_str()),
            _ => None,
        })
        .collect();
    assert!(
        what.len() == 1 && what[0].starts_with("term.local sends no messages"),
        "{what:?}"
    );
}

/// A mission's end is a burst of outputs (every frame terminated at once):
/// once the robot has finished and drained it, its queue gives the room
/// back, and so does its emptied stack, as every robot of a large team
/// otherwise kept them for good.
#[test]
fn a_finished_robot_gives_back_its_outputs_room() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { children: [q] }
  q: { children: [r] }
  r: { children: [s] }
  s: { children: [t] }
  t: { skill: x, until: done }",
        1,
    );
    h.tick(0, &[]);
    assert_eq!(h.stack(0), ["root", "p", "q", "r", "s", "t"]);
    let before = h.events_of(0).len();
    h.tick(100, &[("done", T)]);
    assert!(h.kernels[0].is_finished());
    let burst = h.events_of(0).len() - before;
    assert!(burst > 8, "the end is a burst ({burst} events)");
    assert_eq!(h.kernels[0].out.capacity(), 0);
    assert_eq!(h.kernels[0].stack.capacity(), 0);
}

/// A teammate not heard for longer than `FRESH` keeps only what its next
/// heartbeat is compared with; heard again, it moved exactly when its
/// frames changed meanwhile, as when it was kept whole.
#[test]
fn a_quiet_teammate_is_kept_small_and_moved_only_if_its_frames_changed() {
    let mut h = Harness::new(COURSE, 2);
    h.tick(0, &[]);
    h.beacons();
    let r1 = RobotId(1);
    let first = h.kernels[0].peers.get(&r1).expect("heard").moved.get();
    assert!(first.is_some());
    let same = h.kernels[1].position();
    // Five seconds without a heartbeat from robot 1: quiet.
    for ms in (1000..=5000).step_by(1000) {
        h.tick_one(0, ms, &[]);
    }
    assert!(!h.kernels[0].peers.contains_key(&r1));
    assert!(h.kernels[0].quiet.contains_key(&r1));
    // Heard again where it was: it has not moved since.
    h.kernels[0].peer(Time::from_millis(5100), r1, &same);
    assert_eq!(
        h.kernels[0].peers.get(&r1).expect("heard").moved.get(),
        first
    );
    assert!(!h.kernels[0].quiet.contains_key(&r1));
    // Quiet again, then heard somewhere else: it moved.
    for ms in (6000..=10_000).step_by(1000) {
        h.tick_one(0, ms, &[]);
    }
    assert!(h.kernels[0].quiet.contains_key(&r1));
    h.tick_one(1, 10_000, &[("a_done", T)]);
    let moved_on = h.kernels[1].position();
    assert_ne!(moved_on.frames, same.frames);
    h.kernels[0].peer(Time::from_millis(10_100), r1, &moved_on);
    assert_eq!(
        h.kernels[0].peers.get(&r1).expect("heard").moved.get(),
        Some(Time::from_millis(10_100))
    );
}

/// `first` then `second`, both running `s`; `first` ends at a barrier
/// that only its deadline decides (its release lost).
/// A position heard as from another robot than the one it names (a
/// teammate's heartbeat replayed as from another) is refused and counted:
/// taken, the teammate that ended `a` would have the other one marked
/// departed from `a`, which it still runs.
#[test]
fn a_position_heard_as_from_another_robot_is_refused() {
    let mut h = Harness::new(A_THEN_WAIT, 3);
    h.tick(0, &[]);
    h.tick(100, &[]);
    h.tick_one(2, 200, &[("a_done", T)]);
    let a = h.kernels[0].mission().graph().find("a").expect("a");
    let ended_a = h.kernels[2].position();
    assert_eq!(ended_a.robot, RobotId(2));
    let departed = |h: &Harness| {
        let f = h.kernels[1].stack().last().expect("a frame");
        assert_eq!(f.behavior, a, "robot 1 still runs `a`");
        f.departed
            .as_ref()
            .map(|d| d.iter().collect::<Vec<_>>())
            .unwrap_or_default()
    };
    let heard = h.kernels[1].stats.positions;
    h.kernels[1].peer(Time::from_millis(300), RobotId(0), &ended_a);
    assert_eq!(departed(&h), [], "robot 0 has not left `a`");
    assert_eq!(h.kernels[1].stats.positions, heard, "not taken");
    assert_eq!(
        h.kernels[1].stats.dropped.get(&DropReason::Misattributed),
        Some(&1)
    );
    // From the robot it names, the same position is news.
    h.kernels[1].peer(Time::from_millis(300), RobotId(2), &ended_a);
    assert_eq!(departed(&h), [RobotId(2)]);
}

const TWICE: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [first] }
  first: { team: true, children: [s], until: first_done, next: [second], terminate: term.test-barrier }
  second: { team: true, children: [s], until: never }
  s: { team: true, until: never }";

/// [`TWICE`] with three robots, each ticked twice: all run `s` under
/// `first`.
fn twice_of_three() -> Harness {
    let mut h = Harness::new(TWICE, 3);
    h.tick(0, &[]);
    h.tick(100, &[]);
    h
}

/// The executions of [`TWICE`]: root, first, second and s, each the
/// team's first.
fn twice_ids(h: &Harness) -> [FrameId; 4] {
    let g = h.kernels[0].mission().graph();
    ["root", "first", "second", "s"].map(|name| FrameId {
        team: TeamId::ROOT,
        behavior: g.find(name).expect("behavior"),
        epoch: 1,
    })
}

/// A teammate's position running these executions, root first, each
/// with what it follows: the execution before it in its chain (`false`),
/// or the parent it is the first under (`true`).
fn running(chain: &[(FrameId, Option<(FrameId, bool)>)]) -> Position {
    let frames = chain
        .iter()
        .map(|(id, after)| PosFrame {
            id: *id,
            anchor: after.map(|(a, first)| Anchor {
                behavior: a.behavior,
                epoch: a.epoch,
                first,
            }),
            state: FrameState::Running,
            alloc: None,
            departed: None,
        })
        .collect();
    Position {
        frames,
        ..Position::default()
    }
}

/// A teammate's position in [`TWICE`], running `s` under `first`, or
/// under `second` (after `first`).
fn in_s_under(h: &Harness, parent: &str) -> Position {
    let [root, first, second, s] = twice_ids(h);
    if parent == "first" {
        running(&[
            (root, None),
            (first, Some((root, true))),
            (s, Some((first, true))),
        ])
    } else {
        running(&[
            (root, None),
            (second, Some((first, false))),
            (s, Some((second, true))),
        ])
    }
}

/// The barrier that ends [`TWICE`]'s first execution of `first`, at
/// which robot `r` waits (checked).
fn waiting_at_first(h: &Harness, r: usize) -> InstanceKey {
    let [_, first, ..] = twice_ids(h);
    let key = first_termination(first.behavior);
    assert!(
        h.kernels[r].instances.get(&key).is_some(),
        "robot {r} waits at the barrier"
    );
    key
}

/// [`TWICE`] with two robots: the member ends `first` (and `s` under it)
/// and waits at its barrier. The barrier's key.
fn member_at_the_barrier(h: &mut Harness) -> InstanceKey {
    h.tick(0, &[]);
    assert_eq!(h.stack(1), ["root", "first", "s"]);
    h.tick_one(1, 100, &[("first_done", T)]);
    let key = waiting_at_first(h, 1);
    assert_eq!(h.stack(1), ["root"]);
    assert!(matches!(
        h.kernels[1].popped(),
        Some((_, FrameState::Ending))
    ));
    key
}

/// A leader waiting at a barrier for a teammate still running the behavior
/// waits on while the teammate gets on: its frames changed, or its skill
/// made a step (`Kernel::skill_progressed`, told with its heartbeats), within
/// the slow-wait limit. A teammate sweeping a hall for minutes keeps the
/// same frames throughout; before it told its steps, the barrier's deadline
/// cut its sweep short.
#[test]
fn a_teammate_whose_skill_makes_steps_is_waited_for_however_long_it_works() {
    // The leader ends `first` and waits at its barrier; its teammate runs
    // it on, heard every second, its skill making a step every second until
    // `steps_until`. Is the leader still waiting at `at` seconds?
    let waiting = |steps_until: u64, at: u64| {
        let mut h = Harness::new(TWICE, 2);
        h.tick(0, &[]);
        h.tick_one(0, 100, &[("first_done", T)]);
        let key = waiting_at_first(&h, 0);
        for s in 1..=at {
            if s <= steps_until {
                h.kernels[1].skill_progressed();
            }
            let pos = h.kernels[1].position();
            let now = Time::from_millis(s * 1_000);
            h.kernels[0].peer(now, RobotId(1), &pos);
            h.kernels[0].timer(now);
        }
        h.kernels[0].instances.get(&key).is_some()
    };
    let limit = crate::mission::SLOW_WAIT_MIN.as_secs();
    // No step: waited for the limit, then a timeout and a decision.
    assert!(waiting(0, limit - 10));
    assert!(!waiting(0, limit + 60));
    // Steps every second: waited for ten minutes and on.
    assert!(waiting(600, 600));
    // Once they stop, the limit runs from the last.
    assert!(waiting(600, 600 + limit - 10));
    assert!(!waiting(600, 600 + limit + 60));
}

/// Two executions of one behavior under different parents share an id
/// when the team's count of it is the same in both (a robot that ran it
/// once more than its teammates under the first parent, alone, counts the
/// same as they do under the second). A robot waiting at the barrier that
/// ends the first parent, having ended the behavior there, must not take a
/// teammate running it under the second parent for one behind it: that
/// teammate is ahead, and re-arming the deadline for it left the
/// formation (configuration 5, heavy loss, seed 71) waiting until the
/// stall detector ended the run.
#[test]
fn a_teammate_in_a_same_numbered_execution_under_a_later_parent_is_not_behind() {
    let mut h = Harness::new(TWICE, 2);
    let key = member_at_the_barrier(&mut h);
    let [.., s] = twice_ids(&h);
    assert!(h.kernels[1].recent_ended.contains(&s));
    // Its leader, heard running `s` under `second`: ahead, not awaited.
    let ahead = in_s_under(&h, "second");
    h.kernels[1].peer(Time::from_millis(200), RobotId(0), &ahead);
    assert!(
        !h.kernels[1].awaited_at_work(key),
        "a leader ahead is not waited for"
    );
    // Heard running `s` under `first` instead: still in the execution.
    let behind = in_s_under(&h, "first");
    h.kernels[1].peer(Time::from_millis(300), RobotId(0), &behind);
    assert!(
        h.kernels[1].awaited_at_work(key),
        "a leader behind is waited for"
    );
}

/// Three team behaviors, one inside the other, over a leaf that ends at a
/// barrier.
const NESTED: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [top] }
  top: { team: true, children: [mid] }
  mid: { team: true, children: [leaf] }
  leaf: { team: true, until: leaf_done, terminate: term.test-barrier }";

/// A leader waiting at a barrier waits on for a teammate that runs an
/// execution above the point with nothing below it yet (making that
/// execution's allocation, or expanding it): it is on its way down, from
/// the parent or from further up. Property seed 7435: the barrier's
/// leader took a teammate allocating the point's grandparent for silent
/// and decided on its deadline, 0.1 s after the teammate came down.
#[test]
fn a_leader_waits_for_a_teammate_on_its_way_down_from_further_up() {
    let mut h = Harness::new(NESTED, 2);
    h.tick(0, &[]);
    assert_eq!(h.stack(0), ["root", "top", "mid", "leaf"]);
    h.tick_one(0, 100, &[("leaf_done", T)]);
    let g = h.kernels[0].mission().graph();
    let [root, top, mid, leaf] = ["root", "top", "mid", "leaf"].map(|name| FrameId {
        team: TeamId::ROOT,
        behavior: g.find(name).expect("behavior"),
        epoch: 1,
    });
    let key = first_termination(leaf.behavior);
    assert!(
        h.kernels[0].instances.get(&key).is_some(),
        "the leader waits"
    );
    // Heard in each execution above the point with nothing below it, the
    // teammate is on its way: from the parent, the grandparent, the root.
    let above = [
        vec![
            (root, None),
            (top, Some((root, true))),
            (mid, Some((top, true))),
        ],
        vec![(root, None), (top, Some((root, true)))],
        vec![(root, None)],
    ];
    for (i, chain) in above.iter().enumerate() {
        let mut h = Harness::new(NESTED, 2);
        h.tick(0, &[]);
        h.tick_one(0, 100, &[("leaf_done", T)]);
        // Its heartbeats, sent by robot 1.
        let from = |mut pos: Position| {
            pos.robot = RobotId(1);
            pos
        };
        h.kernels[0].peer(Time::from_millis(200), RobotId(1), &from(running(chain)));
        assert!(
            h.kernels[0].awaited_at_work(key),
            "a teammate in the execution {} levels above the point is on its way",
            i + 1
        );
        // Ending that execution instead, it is not coming down.
        let mut ending = running(chain);
        if let Some(last) = ending.frames.last_mut() {
            last.state = FrameState::Ending;
        }
        h.kernels[0].peer(Time::from_millis(300), RobotId(1), &from(ending));
        assert!(
            !h.kernels[0].awaited_at_work(key),
            "a teammate ending the execution above is not on its way down"
        );
    }
}

/// A teammate's frame running under an execution this robot ended is one
/// this robot will never join: its team's count of that behavior goes past
/// it (`count_past`). Not when the teammate's execution only shares the
/// ended one's id, under another parent (`s` under `second`, where this
/// robot ended `s` under `first`).
#[test]
fn a_frame_under_a_same_numbered_execution_under_another_parent_is_not_counted_past() {
    let mut h = Harness::new(TWICE, 2);
    member_at_the_barrier(&mut h);
    let [_, _, second, s] = twice_ids(&h);
    // Something the teammate runs under `s` (an execution of `second`,
    // numbered 3, stands for it: only the ids are compared).
    let below = FrameId { epoch: 3, ..second };
    let counted = |k: &Kernel| k.org.runs(TeamId::ROOT, second.behavior);
    // The teammate in `s` under `parent`, running `below` under it.
    let under = |parent: &str| {
        let mut p = in_s_under(&h, parent);
        p.frames.extend(running(&[(below, Some((s, true)))]).frames);
        p
    };
    let (under_second, under_first) = (under("second"), under("first"));
    h.kernels[1].peer(Time::from_millis(200), RobotId(0), &under_second);
    assert!(
        counted(&h.kernels[1]) < 3,
        "counted past an execution under another `s`"
    );
    h.kernels[1].peer(Time::from_millis(300), RobotId(0), &under_first);
    assert_eq!(
        counted(&h.kernels[1]),
        3,
        "an execution under the `s` it ended"
    );
}

/// A teammate heard running the successor of an execution this robot runs
/// is done with it, even when none of its recent ends names it: it may
/// have gone past it without running it, converging on teammates further
/// on (a lap behind, it took their epoch of the next behavior). Nothing
/// else would tell this robot, which then waited for it below the
/// execution until a deadline (docs/reliability.md, "A teammate that went
/// past without running it").
#[test]
fn a_teammate_running_the_successor_of_an_execution_departed_from_it() {
    let mut h = twice_of_three();
    let [_, first, ..] = twice_ids(&h);
    let departed = |h: &Harness| {
        let f = (h.kernels[1].stack().iter())
            .find(|f| f.id() == first)
            .expect("robot 1 runs `first`");
        f.departed
            .as_ref()
            .map(|d| d.iter().collect::<Vec<_>>())
            .unwrap_or_default()
    };
    let mut within = in_s_under(&h, "first");
    within.robot = RobotId(2);
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &within);
    assert_eq!(departed(&h), [], "robot 2 still runs `first`");
    let mut past = in_s_under(&h, "second");
    past.robot = RobotId(2);
    assert!(past.ended.is_empty() && past.burned.is_empty());
    h.kernels[1].peer(Time::from_millis(300), RobotId(2), &past);
    assert_eq!(departed(&h), [RobotId(2)]);
}

/// A robot still in an execution answers, with its own heartbeats, a
/// teammate that went on to its successor and waits at a point there: the
/// teammate may wait for it (it is on its way), and without its
/// heartbeats took it for silent, its own going to the team's leader only
/// (found by `no_waiting_across_levels`, RNG seed 60, graph seed
/// 14151179637200551742: a vote's coordinator waited out two members
/// still in the individual behavior before it).
#[test]
fn a_robot_answers_a_teammate_waiting_past_the_execution_it_runs() {
    // Robot 2 went on to `second` and waits there at a point.
    robot_1_answers_robot_2_waiting_at(|[_, first, second, _]| (second, first));
}

/// In [`TWICE`] with three robots, robot 1 runs `first`, and tells its
/// leader only. Robot 2, heard waiting at the end of the execution `at`
/// picks (after the one it also gives), is answered; heard at work there,
/// it waits for nobody and is not.
fn robot_1_answers_robot_2_waiting_at(at: impl Fn([FrameId; 4]) -> (FrameId, FrameId)) {
    let mut h = twice_of_three();
    let ids = twice_ids(&h);
    let (exec, after) = at(ids);
    assert_eq!(audience(&h, 1), [0], "robot 1 tells its leader only");
    let mut waiting = running(&[(ids[0], None), (exec, Some((after, false)))]);
    waiting.robot = RobotId(2);
    if let Some(f) = waiting.frames.last_mut() {
        f.state = FrameState::Ended;
    }
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &waiting);
    assert_eq!(audience(&h, 1), [0, 2], "robot 2 is answered");
    tell(
        &mut h,
        1,
        2,
        Time::from_millis(300),
        &[(ids[0], None), (exec, Some((after, false)))],
    );
    assert_eq!(audience(&h, 1), [0]);
}

/// A member at a barrier whose leader's heartbeat shows the leader past
/// it (the release lost) asks the leader, which answers with the release;
/// but only once the leader has been seen past it for a retry, since the
/// heartbeat may arrive before the release does. A leader not past it is
/// not asked.
#[test]
fn a_member_asks_a_leader_seen_past_its_barrier_after_a_retry() {
    let probe = Harness::new(TWICE, 2);
    let [root, first, ..] = twice_ids(&probe);
    // Past it: running what follows, or done with the mission (nothing
    // running, `first` among the executions it ended).
    let following = in_s_under(&probe, "second");
    let finished = Position {
        ended: vec![Ended {
            id: first,
            parent: Some(root),
        }],
        ..Position::default()
    };
    for past in [following, finished] {
        let mut h = Harness::new(TWICE, 2);
        let key = member_at_the_barrier(&mut h);
        let retry = h.kernels[1].instances.get(&key).expect("waits").retry.get();
        let retry_ms = u64::try_from(retry.as_millis()).expect("a short retry");
        let queries = |k: &mut Kernel| {
            let mut n = 0;
            while let Some(o) = k.poll_output() {
                if let Output::Send(out) = o
                    && out.envelope.instance == key
                    && out.envelope.body == Body::Query
                {
                    assert_eq!(out.to, Recipients::One(RobotId(0)));
                    n += 1;
                }
            }
            n
        };
        let at = |n: u64| Time::from_millis(100 + n * retry_ms);
        let in_first = in_s_under(&h, "first");
        h.kernels[1].peer(at(1), RobotId(0), &in_first);
        assert_eq!(queries(&mut h.kernels[1]), 0, "not past: nothing to ask");
        h.kernels[1].peer(at(2), RobotId(0), &past);
        assert_eq!(queries(&mut h.kernels[1]), 0, "first seen past: not yet");
        h.kernels[1].peer(at(3), RobotId(0), &past);
        assert_eq!(
            queries(&mut h.kernels[1]),
            1,
            "past for a retry: ask ({past:?})"
        );
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// The filter of the executions a robot ended has the bit of every one
    /// it remembers (a missing bit would make `count_past` miss it), and
    /// stays sparse as executions come and go.
    #[test]
    fn the_filter_of_ended_executions_misses_none(
        ended in proptest::collection::vec((0u64..6, 0u32..5, 1u32..40), 0..200),
    ) {
        let h = Harness::new(
            "start: root\ndefaults: { terminate: term.local }\nbehaviors:\n  root: { skill: idle, until: done }",
            1,
        );
        let mut k = h.kernels.into_iter().next().expect("one robot");
        for (team, behavior, epoch) in ended {
            let id = FrameId { team: TeamId(team), behavior: BehaviorId(behavior), epoch };
            k.note_ended(id, None);
            for e in k.recent_ended.iter() {
                proptest::prop_assert!(k.recent_ended.contains(&e.id));
            }
            proptest::prop_assert!(k.recent_ended.filter().count_ones() as usize <= 2 * position::RECENT + 1);
        }
    }
}

/// The individual behavior `p` ends for r1 alone: r1 leaves the subteam it
/// led (`q`: r1, r2, r3) while r2 and r3 go on in it.
const LEADER_LEAVES: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { team: false, children: [y, q], until: stop, next: [z] }
  y: { skill: w, members: 1 }
  q: { skill: w }
  z: { team: false, skill: w }";

fn audience(h: &Harness, r: usize) -> Vec<u32> {
    h.kernels[r].beacon_audience().iter().map(|x| x.0).collect()
}

/// A leader that leaves its team (the individual behavior above it ended
/// for it alone) answers the members that still send it their heartbeats,
/// so that they learn it left and hear each other through the next leader;
/// and only for a while (found by `no_waiting_across_levels`: a member a
/// lap behind, heard by nobody, was taken for silent at the next point).
#[test]
fn a_leader_that_left_answers_its_members_for_a_while() {
    let mut h = Harness::new(LEADER_LEAVES, 4);
    h.tick(0, &[("stop", F)]);
    assert_eq!(h.stack(1), ["root", "p", "q"]);
    assert_eq!(
        audience(&h, 3),
        [0, 1],
        "r3 sends to the root's leader and to q's"
    );
    h.tick_one(1, 100, &[("stop", T)]);
    assert_eq!(h.stack(1), ["root", "z"]);
    // r2 and r3 still send to r1; r1 answers them.
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0, 2, 3]);
    // They learn that r1 left: r2 leads q now, and r3 sends to it.
    h.heartbeats();
    assert_eq!(audience(&h, 3), [0, 2]);
    assert_eq!(audience(&h, 2), [0, 1, 3], "a leader sends to every member");
    // r1 answers no more once the window has passed, though r2, q's
    // leader, still sends it heartbeats.
    h.now = h.now + position::ANSWER_LEFT + std::time::Duration::from_millis(100);
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0]);
}

/// The team behavior `p` ends by its own `until` for r2 ahead of its
/// teammates (its termination, a barrier, waits for them all): r2 leaves
/// the subteam of `q` (r1 leads it; r2, r3) while r1 and r3 go on in it,
/// through `q` and up to the barrier of `q2`, which r2 never ran.
const MEMBER_ENDS_AHEAD: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { team: true, children: [y, q], until: stop, terminate: term.test-barrier }
  y: { skill: w, members: 1 }
  q: { team: true, skill: w, until: qdone, next: [q2] }
  q2: { team: true, skill: w, until: q2done, terminate: term.test-barrier }";

/// A member that left a subteam (it ended the behavior above ahead of its
/// team) answers the subteam's leader once that leader waits at a point,
/// so that it leaves the member out rather than wait for it there; and
/// not while the leader is at work, waiting for nobody (found by
/// `no_waiting_across_levels`, graph seed 10512915990778792624: the
/// subteam's leader waited 31 s for two members gone to the parent's
/// `term.majority` barrier, which decided only 66 s later).
#[test]
fn a_member_that_left_answers_its_subteam_leader_waiting_at_a_point() {
    let mut h = Harness::new(MEMBER_ENDS_AHEAD, 4);
    h.tick(0, &[("stop", F), ("qdone", F)]);
    assert_eq!(h.stack(2), ["root", "p", "q"]);
    assert_eq!(
        audience(&h, 1),
        [0, 2, 3],
        "q's leader sends to its members"
    );
    h.tick_one(2, 100, &[("stop", T)]);
    assert_eq!(h.stack(2), ["root"], "r2 waits at p's termination");
    assert_eq!(h.stack(1), ["root", "p", "q"]);
    // r1 still sends to r2, at work: r2 does not answer.
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0]);
    // r1 goes on to q2 and waits at its barrier: r2 answers it.
    h.tick_one(1, 200, &[("qdone", T), ("q2done", F)]);
    assert_eq!(h.stack(1), ["root", "p", "q2"]);
    h.tick_one(1, 300, &[("q2done", T)]);
    let key = barrier_at(
        &h,
        1,
        h.kernels[1].mission().graph().find("q2").expect("q2"),
    );
    assert!(!left_out(&h, 1, key, RobotId(2)), "r2 awaited at first");
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0, 1]);
    // r1 learns that r2 left, and leaves it out of the barrier.
    h.heartbeats();
    assert!(left_out(&h, 1, key, RobotId(2)), "r2 left out");
    assert!(!left_out(&h, 1, key, RobotId(3)), "r3 awaited");
}

/// A root team's leader that finished the mission runs no frame and
/// relays nobody's departures: the next member relays them then, so
/// that every member learns of the teammates that finish after it and
/// leaves them out alike. Members that had heard of different finished
/// teammates made different silent allocations, round after round, and
/// waited for each other's subteams until their deadlines (found by
/// `no_waiting_across_levels`, graph seed 14038951268081933415).
#[test]
fn the_next_member_relays_the_root_once_its_leader_finished() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { children: [a], until: done }
  a: { team: true, skill: w, until: a_done }",
        4,
    );
    h.tick(0, &[("done", F), ("a_done", F)]);
    h.heartbeats();
    assert_eq!(audience(&h, 3), [0], "r0 leads the root and `a`");
    h.tick_one(0, 100, &[("done", T)]);
    assert!(h.stack(0).is_empty(), "r0 finished");
    h.heartbeats();
    h.heartbeats();
    assert_eq!(
        audience(&h, 1),
        [0, 2, 3],
        "r1 leads `a` and relays the root"
    );
    assert_eq!(
        audience(&h, 3),
        [0, 1],
        "r3 still sends to the root's leader"
    );
    // r2 finishes: r1 hears it and tells r3, which r2 never sent to.
    h.tick_one(2, 200, &[("done", T)]);
    assert!(h.stack(2).is_empty(), "r2 finished");
    for _ in 0..3 {
        h.heartbeats();
    }
    let root = &h.kernels[3].stack()[0];
    assert!(
        root.departed
            .as_ref()
            .is_some_and(|d| d.contains(RobotId(2))),
        "r3 learnt that r2 left the root"
    );
}

/// `a`, then an allocation under `b`: one robot to `y`, the others to the
/// team behavior `q`, which ends at a barrier.
const A_THEN_Q: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: a_done, next: [b] }
  b: { team: true, children: [y, q] }
  y: { skill: w, members: 1 }
  q: { team: true, skill: w, until: q_done, terminate: term.test-barrier }";

/// [`A_THEN_Q`] with three robots: r1 and r2 took `q`, and r1, done with
/// it, waits at its barrier; r0 is still in `a`.
fn r1_waiting_at_q() -> Harness {
    r1_waiting_at_q_in(A_THEN_Q)
}

/// [`r1_waiting_at_q`] in `graph`, a variant of [`A_THEN_Q`].
fn r1_waiting_at_q_in(graph: &str) -> Harness {
    let mut h = Harness::new(graph, 3);
    h.tick(0, &[("a_done", F), ("q_done", F)]);
    h.heartbeats();
    for r in [1, 2] {
        h.tick_one(r, 100, &[("a_done", T)]);
        assert_eq!(h.stack(r), ["root", "b", "q"]);
    }
    h.tick_one(1, 150, &[("q_done", T)]);
    h
}

/// A teammate's position in [`A_THEN_Q`]: in `b`#1, after `a`, running
/// `y` in a subteam this robot does not know.
fn in_y_elsewhere(h: &Harness) -> Position {
    let g = h.kernels[1].mission().graph();
    let [root, a, b, y] = ["root", "a", "b", "y"].map(|n| g.find(n).expect("behavior"));
    let b_id = FrameId {
        team: TeamId::ROOT,
        behavior: b,
        epoch: 1,
    };
    let at = |behavior| FrameId { behavior, ..b_id };
    let elsewhere = FrameId {
        team: TeamId(0xfeed),
        behavior: y,
        epoch: 1,
    };
    running(&[
        (at(root), None),
        (b_id, Some((at(a), false))),
        (elsewhere, Some((b_id, true))),
    ])
}

/// A leader waiting at a point in a subteam waits on for a teammate it
/// counts there but hears in the execution above, in another subteam (or
/// in none): the two took that allocation from different views, and the
/// split heals within a heartbeat or two. Found by
/// `no_waiting_across_levels` (RNG seed 51, graph seed
/// 3675743155736443249): a member a lap behind allocated knowing that a
/// teammate had finished since its leader allocated; the leader's
/// deadline fell in the 60 ms before the split was seen.
#[test]
fn a_leader_waits_for_a_teammate_split_off_in_the_execution_above() {
    let mut h = r1_waiting_at_q();
    let g = h.kernels[1].mission().graph();
    let [root, a, b] = ["root", "a", "b"].map(|n| g.find(n).expect("behavior"));
    let q_team = h.kernels[1].popped().map(|(f, _)| f.team).expect("q ended");
    let key = InstanceKey {
        team: q_team,
        behavior: g.find("q").expect("q"),
        kind: Kind::Terminate,
        epoch: 1,
        round: 0,
    };
    assert!(h.kernels[1].instances.get(&key).is_some(), "r1 waits at q");
    let root_id = FrameId {
        team: TeamId::ROOT,
        behavior: root,
        epoch: 1,
    };
    let b_id = FrameId {
        team: TeamId::ROOT,
        behavior: b,
        epoch: 1,
    };
    let a_id = FrameId {
        behavior: a,
        ..b_id
    };
    let mut split = in_y_elsewhere(&h);
    split.robot = RobotId(2);
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &split);
    assert!(
        h.kernels[1].awaited_at_work(key),
        "a teammate in another subteam of `b` is on its way"
    );
    // Heard in a later execution of `b`: not in the one above the point.
    let mut later = running(&[
        (root_id, None),
        (FrameId { epoch: 2, ..b_id }, Some((a_id, false))),
    ]);
    later.robot = RobotId(2);
    h.kernels[1].peer(Time::from_millis(250), RobotId(2), &later);
    assert!(
        !h.kernels[1].awaited_at_work(key),
        "not split off: {later:?}"
    );
}

/// A robot waiting at a termination below an allocation heals a split of
/// that allocation too, as one running a skill does: found by
/// `no_waiting_across_levels` (RNG seed 1511, graph seed
/// 15491346240280064998, no faults). A member that came late took its
/// subteam from a later view of the silent allocation above and ended it
/// at once; it waited at that subteam's termination for its leader, and
/// the leader waited at its own subteam's termination for it, each
/// hearing the other's other allocation, until the leader's deadline.
/// Only a teammate of the subteam it waits in makes it heal.
#[test]
fn a_robot_waiting_at_a_termination_heals_an_allocation_split_above() {
    let h = r1_waiting_at_q();
    assert!(
        matches!(h.kernels[1].popped(), Some((_, FrameState::Ending))),
        "r1 waits at q's barrier"
    );
    r1_heals_the_split_above_on_r2_only(h);
}

/// So does a robot waiting at the synchronization after it (found by
/// `no_waiting_across_levels`, RNG seed 2200, graph seed
/// 8970543473821155539: a member waited at its subteam's `sync.leader`
/// for a leader that came to the allocation above and allocated from
/// another view, and the member's deadline fell 0.1 s later).
#[test]
fn a_robot_waiting_at_a_synchronization_heals_an_allocation_split_above() {
    let graph = A_THEN_Q.replace(
        "q_done, terminate: term.test-barrier }",
        "q_done, next: [q1, q2], sync: sync.test-never }\n  q1: { team: true, skill: w }\n  q2: { team: true, skill: w }",
    );
    let h = r1_waiting_at_q_in(&graph);
    assert!(
        matches!(h.kernels[1].popped(), Some((_, FrameState::Ended))),
        "r1 waits at q's synchronization"
    );
    r1_heals_the_split_above_on_r2_only(h);
}

/// r1, waiting at q's end, hears r0 (not in q's subteam), then r2 (in it),
/// each with another allocation of `b`#1: it allocates `b` again on r2's
/// word only.
fn r1_heals_the_split_above_on_r2_only(mut h: Harness) {
    let old_q = h.kernels[1].popped().map(|(f, _)| f.team).expect("q ended");
    let (round, print) = h.kernels[1].stack[1].alloc_print().expect("b allocated");
    let mut split = in_y_elsewhere(&h);
    split.frames[1].alloc = Some((round, print ^ 1));
    // r0 (in `y`, not in q's subteam) with the other allocation: r1 does
    // not wait for it, and leaves that split to robots at work.
    split.robot = RobotId(0);
    h.kernels[1].peer(Time::from_millis(180), RobotId(0), &split);
    assert_eq!(h.kernels[1].stack[1].round, round, "r1 waits on at q");
    split.robot = RobotId(2);
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &split);
    assert_eq!(
        h.kernels[1].stack[1].round,
        round + 1,
        "r1 allocates `b` again, in the next round"
    );
    assert!(
        h.kernels[1].popped().is_none_or(|(f, _)| f.team != old_q),
        "no longer waiting at q in the old subteam"
    );
}

/// A member a lap behind answers a teammate that went through an
/// allocation it has yet to make, counts it a member of the new team and
/// waits for it at a point there: the teammate hears it on its way.
/// Teammates in step, or at work, are not answered.
#[test]
fn a_member_behind_answers_the_team_it_has_yet_to_join() {
    let mut h = Harness::new(A_THEN_Q, 3);
    h.tick(0, &[("a_done", F), ("q_done", F)]);
    h.heartbeats();
    assert!(h.kernels.iter().all(|k| k.answering.is_none()), "in step");
    // r1 ends `a` and leads q (r1, r2); r2 is still in `a`.
    h.tick_one(1, 100, &[("a_done", T)]);
    assert_eq!(h.stack(1), ["root", "b", "q"]);
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0], "r1 at work in q waits for nobody");
    // r1 ends q and waits at its barrier: r2 answers it.
    h.tick_one(1, 150, &[("q_done", T)]);
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0, 1], "r2 answers q's leader");
    // Once r2 is in q too, it sends to its leader as a member, and answers
    // nobody.
    h.tick_one(2, 200, &[("a_done", T)]);
    assert_eq!(h.stack(2), ["root", "b", "q"]);
    h.heartbeats();
    assert!(h.kernels[2].answering.is_none());
    assert_eq!(audience(&h, 2), [0, 1]);
}

/// While a team's leader is heard elsewhere (a lap behind, on its way),
/// the lowest-id member there relays the team's heartbeats as a leader
/// does, and the others send theirs to it too: two members that took one
/// subteam from different views of the allocation above (two ids) heard
/// only the absent leader, not each other, and saw the split only when it
/// came, after a deadline (found by `no_waiting_across_levels`, graph
/// seed 1189108377300224787). Once the leader is there, the members send
/// to it alone again.
#[test]
fn a_member_relays_the_teams_heartbeats_while_its_leader_is_a_lap_behind() {
    let mut h = Harness::new(A_THEN_Q, 4);
    h.tick(0, &[("a_done", F), ("q_done", F)]);
    h.heartbeats();
    // r2 and r3 end `a` and take q (r1, r2, r3), led by r1, still in `a`;
    // they wait at q's barrier.
    for r in [2, 3] {
        h.tick_one(r, 100, &[("a_done", T)]);
        assert_eq!(h.stack(r), ["root", "b", "q"]);
        h.tick_one(r, 150, &[("q_done", T)]);
    }
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0, 1], "r1 not heard yet");
    // r1 answers them (a team it has yet to join): heard away, r2 relays.
    h.heartbeats();
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0, 1, 3], "r2 relays for q");
    assert_eq!(audience(&h, 3), [0, 1, 2], "r3 sends to r2 too");
    // r1 joins q: its members send to it alone.
    h.tick_one(1, 200, &[("a_done", T)]);
    h.heartbeats();
    assert_eq!(audience(&h, 3), [0, 1]);
}

/// A member waiting at a point past one its leader has not reached yet
/// (the leader still runs the execution before) relays the team's
/// heartbeats too: members that took different successors at a point
/// where nobody synchronizes heard only their leader, a lap behind, and
/// never saw the split (found by `no_waiting_across_levels`, graph seed
/// 17570084640527683413). At work, or once the leader is there, nothing
/// changes.
#[test]
fn a_member_waiting_past_a_point_its_leader_has_not_reached_relays() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: a_done, next: [b] }
  b: { team: true, skill: w, until: b_done, terminate: term.test-barrier }",
        3,
    );
    h.tick(0, &[("a_done", F), ("b_done", F)]);
    h.heartbeats();
    for r in [1, 2] {
        h.tick_one(r, 100, &[("a_done", T)]);
        assert_eq!(h.stack(r), ["root", "b"]);
    }
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0], "at work in b, r1 sends to r0 alone");
    for r in [1, 2] {
        h.tick_one(r, 150, &[("b_done", T)]);
    }
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0, 2], "r1 relays while r0 is still in a");
    assert_eq!(audience(&h, 2), [0, 1]);
    h.tick_one(0, 200, &[("a_done", T)]);
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0]);
}

/// A member waiting at a point below an execution its teammates ended
/// (each ends `b` on its own: a silent termination) answers nobody, but
/// a teammate that ended it answers the member's heartbeats: the team's
/// leader, past `b` too, does not report who left it, and the member
/// would wait for it until its deadline (found by
/// `no_waiting_across_levels`, graph seed 16977040845566393922).
#[test]
fn a_teammate_that_ended_the_execution_answers_one_waiting_below_it() {
    let mut h = Harness::new(
        "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [b] }
  b: { team: true, children: [c], until: b_done, next: [d] }
  c: { team: true, skill: w, until: c_done, terminate: term.test-barrier }
  d: { team: true, skill: w }",
        3,
    );
    h.tick(0, &[("b_done", F), ("c_done", F)]);
    // r0, the root team's leader, then r2 end `b`; r1 ends `c` and waits
    // at its barrier.
    h.tick_one(0, 100, &[("b_done", T)]);
    h.tick_one(2, 100, &[("b_done", T)]);
    h.tick_one(1, 100, &[("c_done", T)]);
    assert_eq!(h.stack(2), ["root", "d"]);
    // r1 learns from r0's heartbeat that r0 ended `b`: r1 leads the team
    // below `b` now, and sends its heartbeats to r2, which answers.
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0]);
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0, 1], "r2 answers r1");
    h.heartbeats();
    let left_out = h
        .events_of(1)
        .into_iter()
        .any(|e| matches!(e, Event::LeftOut { members, .. } if members.contains(&RobotId(2))));
    assert!(left_out, "r1 no longer waits for r2");
}

/// A team that loops `a`, `b`, `a`, ... and ends each behavior on its own
/// (`term.local`): a member may run ahead of its teammates by any number
/// of executions.
const LOOP_LOCAL: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: step, next: [b] }
  b: { team: true, skill: w, until: step, next: [a] }";

/// A teammate many executions behind, in one this robot ran under the
/// same parent execution, is on this robot's way, not on a diverged
/// history, even once the ends the robot remembers (`RECENT`) no longer
/// name it. Found by `random_teams_survive_network_faults` (RNG seed 112,
/// graph seed 9820052158066147912, no faults): a member done with a
/// `term.local` decomposition went on alone through more than eight
/// behaviors, then took its leader, still in the decomposition, for
/// another history and went back into it; the leader followed it into a
/// new execution of the decomposition, and the two did so every lap
/// until the time limit.
#[test]
fn a_teammate_many_executions_behind_is_not_a_diverged_history() {
    let mut h = Harness::new(LOOP_LOCAL, 2);
    h.tick(0, &[("step", Value::Bool(false))]);
    // Robot 1 alone ends an execution every other tick: 20 of them, far
    // more than the ends it remembers.
    for n in 1..=40 {
        h.tick_one(1, 100 * n, &[("step", Value::Bool(n % 2 == 1))]);
    }
    let g = h.kernels[1].mission().graph();
    let a = g.find("a").expect("a");
    let root = g.find("root").expect("root");
    let top = h.kernels[1]
        .stack()
        .last()
        .map(|f| f.id())
        .expect("running");
    assert!(
        top.epoch > position::RECENT as u32,
        "robot 1 ran ahead: {top:?}"
    );
    assert!(
        !h.kernels[1]
            .recent_ended
            .iter()
            .any(|e| e.id.behavior == a && e.id.epoch == 1),
        "robot 1 no longer remembers ending a@1"
    );
    // Robot 0, the team's lowest id, is still in the first `a`.
    let id = |behavior, epoch| FrameId {
        team: TeamId::ROOT,
        behavior,
        epoch,
    };
    let mut behind = running(&[(id(root, 1), None), (id(a, 1), Some((id(root, 1), true)))]);
    behind.robot = RobotId(0);
    h.kernels[1].peer(Time::from_millis(4_100), RobotId(0), &behind);
    h.drain(1);
    assert_eq!(
        h.kernels[1].stack().last().map(|f| f.id()),
        Some(top),
        "robot 1 stays where it is"
    );
    assert!(
        !h.events_of(1)
            .iter()
            .any(|e| matches!(e, Event::Split { .. })),
        "no split"
    );
}

/// A loop like [`LOOP_LOCAL`]'s, left after four laps for `z`, whose end
/// is a barrier.
const LOOP_TO_BARRIER: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: step, next: [b], pre: 'runs < 4' }
  b: { team: true, skill: w, until: step, next: [c] }
  c: { team: true, skill: w, until: step, next: [a, z] }
  z: { team: true, skill: w, until: step, terminate: term.test-barrier }";

/// Two robots on `graph` (whose skills end on `step`); robot 0 alone runs
/// on, `step` held every other tick, until it waits at the barrier that
/// ends `barrier`'s first execution. Returns the harness, the ticks it
/// took (100 ms each) and the barrier's instance.
fn alone_to_the_barrier(graph: &str, barrier: &str) -> (Harness, u64, InstanceKey) {
    let mut h = Harness::new(graph, 2);
    h.tick(0, &[("step", Value::Bool(false))]);
    let behavior = (h.kernels[0].mission().graph().find(barrier)).expect("behavior");
    let mut n = 0;
    while h.kernels[0].popped().is_none() {
        n += 1;
        assert!(n < 400, "robot 0 never reached {barrier}: {:?}", h.stack(0));
        h.tick_one(0, 100 * n, &[("step", Value::Bool(n % 2 == 1))]);
    }
    let key = first_termination(behavior);
    assert!(
        h.kernels[0].instances.get(&key).is_some(),
        "waits at {barrier}"
    );
    (h, n, key)
}

/// A leader at a barrier waits for a teammate many behaviors behind on its
/// way, heard at work: slow, not silent, even once the ends the leader
/// remembers (`RECENT`) no longer name the teammate's execution. Found by
/// `no_waiting_across_levels` (RNG seed 20, graph seed
/// 16216504317419966665): a leader waited out its deadline for a teammate
/// two behaviors behind, having ended more than eight executions since.
#[test]
fn a_leader_waits_for_a_teammate_many_behaviors_behind() {
    let (mut h, n, key) = alone_to_the_barrier(LOOP_TO_BARRIER, "z");
    let g = h.kernels[0].mission().graph();
    let [root, a, b] = ["root", "a", "b"].map(|n| g.find(n).expect("behavior"));
    let id = at_root;
    assert!(!h.kernels[0].recent_ended.contains(&id(a, 1)));
    // Robot 1, heard at work in the first `a`, then in the first `b`.
    let now = |k: u64| Time::from_millis(100 * n + 100 * k);
    tell(
        &mut h,
        0,
        1,
        now(1),
        &[(id(root, 1), None), (id(a, 1), Some((id(root, 1), true)))],
    );
    tell(
        &mut h,
        0,
        1,
        now(2),
        &[(id(root, 1), None), (id(b, 1), Some((id(a, 1), false)))],
    );
    assert!(
        h.kernels[0].awaited_at_work(key),
        "a teammate at work many behaviors behind is awaited"
    );
    // Heard in an execution of `b` robot 0 never started: not behind.
    let beyond = [(id(root, 1), None), (id(b, 40), Some((id(a, 40), false)))];
    tell(&mut h, 0, 1, now(3), &beyond);
    assert!(!h.kernels[0].awaited_at_work(key), "not behind: {beyond:?}");
}

/// Robot `to` hears robot `from` at `now` running `chain` (as [`running`]).
fn tell(
    h: &mut Harness,
    to: usize,
    from: u32,
    now: Time,
    chain: &[(FrameId, Option<(FrameId, bool)>)],
) {
    let mut pos = running(chain);
    pos.robot = RobotId(from);
    h.kernels[to].peer(now, RobotId(from), &pos);
}

/// A robot answers a teammate waiting at a point in an execution of its
/// team it has yet to start, any number of behaviors ahead (not only the
/// successor of its own): once the team's leader has gone by too, the
/// teammate leads the point and waits for it without hearing it. Found by
/// `no_waiting_across_levels` (RNG seed 243, graph seed
/// 1730459986348358178): under `term.local` a robot went round the root's
/// cycle a lap ahead and waited 90 s at an allocation for a teammate it
/// never heard, then decided without it at its deadline.
#[test]
fn a_robot_answers_a_teammate_waiting_laps_ahead() {
    // Robot 2 waits at the end of the team's second `first`, which robot 1
    // has yet to start (it came after `second`, not after robot 1's `first`).
    robot_1_answers_robot_2_waiting_at(|[_, first, second, _]| {
        (FrameId { epoch: 2, ..first }, second)
    });
}

/// A robot still in an execution answers a teammate that ended it and
/// leads its end (its heartbeat reports who departed) when that teammate is
/// not the leader this robot sends to there: the two counted different
/// teammates departed above it, and the teammate waits at the barrier for
/// it without hearing it. Found by `no_waiting_across_levels` (RNG seed
/// 281, graph seed 5261739610812070048): the team's two lowest ids had
/// left an individual behavior; members late into it did not know, sent
/// their heartbeats to the second, which did not answer, and the robot
/// leading the barrier of a team behavior under it waited out its deadline.
#[test]
fn a_robot_answers_a_teammate_leading_the_end_of_the_execution_it_runs() {
    let mut h = twice_of_three();
    let [root, first, ..] = twice_ids(&h);
    assert_eq!(audience(&h, 1), [0], "robot 1 tells its leader only");
    let at_the_end = |r: u32| {
        let mut p = running(&[(root, None), (first, Some((root, true)))]);
        p.robot = RobotId(r);
        if let Some(f) = p.frames.last_mut() {
            f.state = FrameState::Ended;
            let mut d = MemberSet::empty(3);
            d.insert(RobotId(0));
            d.insert(RobotId(r));
            f.departed = Some(d);
        }
        p
    };
    let answers = |h: &Harness, r: u32| {
        (h.kernels[1].answering.as_ref()).is_some_and(|a| a.contains(RobotId(r)))
    };
    // Robot 2 leads the end (robot 0 departed, as robot 1 does not know):
    // answered.
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &at_the_end(2));
    assert!(answers(&h, 2), "{:?}", audience(&h, 1));
    assert!(audience(&h, 1).contains(&2), "{:?}", audience(&h, 1));
    // Robot 1's leader there, at the end: robot 1 sends to it anyway.
    let mut h = twice_of_three();
    h.kernels[1].peer(Time::from_millis(200), RobotId(0), &at_the_end(0));
    assert!(!answers(&h, 0));
}

/// Two robots take different successors of a point each decides alone (a
/// precondition held for one of them only); both lead into the same
/// behavior. A robot waiting at a point there waits on for a teammate heard
/// at work in the other successor: it is on its way. Found by
/// `no_waiting_across_levels` (RNG seed 245, graph seed
/// 2090918748688623487).
#[test]
fn a_robot_waits_for_a_teammate_on_another_way_into_its_execution() {
    const FORK: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: a_done, next: [b, c] }
  b: { team: true, skill: w, until: b_done, pre: 'pb', next: [d] }
  c: { team: true, skill: w, until: c_done, pre: 'not pb', next: [d] }
  d: { team: true, skill: w, until: d_done, terminate: term.test-barrier }";
    let mut h = Harness::new(FORK, 2);
    let off = [("a_done", F), ("b_done", F), ("c_done", F), ("d_done", F)];
    h.tick(0, &off);
    h.tick_one(0, 100, &[("pb", T), ("a_done", T)]);
    h.tick_one(0, 200, &[("b_done", T)]);
    h.tick_one(0, 300, &[("d_done", T)]);
    let g = h.kernels[0].mission().graph();
    let [root, a, c, d] = ["root", "a", "c", "d"].map(|n| g.find(n).expect("behavior"));
    let key = first_termination(d);
    assert!(
        h.kernels[0].instances.get(&key).is_some(),
        "robot 0 waits at d"
    );
    let id = |team, behavior| FrameId {
        team,
        behavior,
        epoch: 1,
    };
    let heard = |h: &mut Harness, ms: u64, team: TeamId, behavior| {
        let mut p = running(&[
            (id(TeamId::ROOT, root), None),
            (id(team, behavior), Some((id(team, a), false))),
        ]);
        p.robot = RobotId(1);
        h.kernels[0].peer(Time::from_millis(ms), RobotId(1), &p);
    };
    heard(&mut h, 350, TeamId::ROOT, a);
    heard(&mut h, 400, TeamId::ROOT, c);
    assert!(
        h.kernels[0].awaited_at_work(key),
        "a teammate in `c` is on its way to `d`"
    );
    // In a later execution of `d`: not on its way to this one.
    let mut later = running(&[
        (id(TeamId::ROOT, root), None),
        (
            FrameId {
                epoch: 2,
                ..id(TeamId::ROOT, d)
            },
            Some((id(TeamId::ROOT, c), false)),
        ),
    ]);
    later.robot = RobotId(1);
    h.kernels[0].peer(Time::from_millis(450), RobotId(1), &later);
    assert!(!h.kernels[0].awaited_at_work(key), "{later:?}");
}

/// A teammate heard in an execution of a successor of this robot's
/// execution that this robot has yet to start went past that execution
/// without running it (it took another way, or converged on teammates
/// further on): it is marked departed from it and left out of its points,
/// its end's barrier included (it sends no `Done` there). Found by
/// `no_waiting_across_levels` (RNG seeds 323 and 384, graph seeds
/// 9461620870857060531 and 2527497076677607155).
#[test]
fn a_teammate_that_went_past_an_execution_without_running_it_is_left_out_of_it() {
    let mut h = twice_of_three();
    let [root, first, second, _] = twice_ids(&h);
    let barrier = waiting_at_first(&h, 1);
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
    // Robot 2 runs `second` but did not come from robot 1's `first` (its
    // anchor is the root: it converged there).
    tell(
        &mut h,
        1,
        2,
        Time::from_millis(200),
        &[(root, None), (second, Some((root, true)))],
    );
    assert_gone_from(
        &h,
        1,
        first,
        barrier,
        RobotId(2),
        "robot 2 is done with `first`",
    );
}

/// A teammate that converged past an execution onto its successor, never
/// having run it, is left out of its allocation (it sends nothing there),
/// unless it coordinates it: it may have run it and decided, its end no
/// longer among those its heartbeat lists. Found by
/// `no_waiting_across_levels` (RNG seed 7816, graph seed
/// 216557608976084570): a coordinator waited 14.5 s for the costs of a
/// teammate that had converged past the allocation's execution.
#[test]
fn a_teammate_converged_past_an_allocation_is_left_out_of_it_unless_it_leads_it() {
    const A_B: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, children: [x, y], allocate: alloc.test-never, next: [b] }
  x: { team: true, skill: w }
  y: { team: true, skill: w }
  b: { team: true, until: never }";
    let mut h = Harness::new(A_B, 3);
    h.tick(0, &[]);
    let [root, a, b] = behaviors(&h, 0, ["root", "a", "b"]);
    let id = |behavior| FrameId {
        team: TeamId::ROOT,
        behavior,
        epoch: 1,
    };
    let alloc = InstanceKey {
        kind: Kind::Allocate,
        ..first_termination(a)
    };
    for r in 0..3 {
        assert!(h.kernels[r].instances.get(&alloc).is_some(), "r{r} waits");
    }
    // Robot 2, heard by robot 0 (which coordinates) in `b`#1 after `a`#1.
    let past = [(id(root), None), (id(b), Some((id(a), false)))];
    tell(&mut h, 0, 2, Time::from_millis(200), &past);
    assert!(left_out(&h, 0, alloc, RobotId(2)), "robot 2 left out");
    // Robot 0, the coordinator, heard so by robot 1: it stays.
    tell(&mut h, 1, 0, Time::from_millis(200), &past);
    assert!(!left_out(&h, 1, alloc, RobotId(0)), "the coordinator stays");
}

/// A teammate that came from an earlier execution of this robot's
/// behavior into a successor this robot has yet to start, a way that leads
/// back round, may still come to this robot's execution: it stays in its
/// points. Not when it waits there at its successor's end: it comes round
/// only once its team has ended that successor, after this robot got there
/// past its own execution, so waiting for it at this robot's point is
/// waiting in a circle; it is left out. Found by `no_waiting_across_levels`
/// (RNG seed 7900, graph seed 11260683622264470111): r2, in `b4`#4 after
/// `b3`#3, waited 127 s at `b4`#4's `term.majority` for teammates who waited
/// for it at `b3`#4's `sync.elected-leader`.
#[test]
fn a_teammate_waiting_at_the_end_of_a_successor_is_left_out_of_the_point_before_it() {
    const A_B: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: a_done, next: [b, c], sync: sync.test-never }
  b: { team: true, skill: w, until: b_done, next: [a] }
  c: { team: true, skill: w }";
    let mut h = Harness::new(A_B, 3);
    let [root, a, b] = behaviors(&h, 0, ["root", "a", "b"]);
    // Robot 0's count of `a` is past #1 (a teammate's word raised it): it
    // starts `a`#2, ends it, and waits at its synchronization.
    h.kernels[0].org.runs_at_least(TeamId::ROOT, a, 1);
    h.tick_one(0, 0, &[("a_done", F), ("b_done", F)]);
    h.tick_one(0, 100, &[("a_done", T)]);
    let sync = InstanceKey {
        kind: Kind::Sync,
        epoch: 2,
        ..first_termination(a)
    };
    assert!(h.kernels[0].instances.get(&sync).is_some(), "robot 0 waits");
    // Robot 2 runs `b`#1 after `a`#1; then it waits at `b`#1's end.
    let mut pos = running(&[
        (at_root(root, 1), None),
        (at_root(b, 1), Some((at_root(a, 1), false))),
    ]);
    pos.robot = RobotId(2);
    h.kernels[0].peer(Time::from_millis(150), RobotId(2), &pos);
    assert!(!left_out(&h, 0, sync, RobotId(2)), "it may come round");
    pos.frames[1].state = FrameState::Ending;
    h.kernels[0].peer(Time::from_millis(200), RobotId(2), &pos);
    assert!(left_out(&h, 0, sync, RobotId(2)), "it waits for the team");
}

/// A robot whose deadline falls at a point with counted teammates it has
/// never heard (their heartbeats go to a leader elsewhere) calls them once:
/// its heartbeats go to them for two retries, and the deadline waits that
/// long; then it decides without them as before. Found by
/// `no_waiting_across_levels` (RNG seeds 461 and 477, graph seeds
/// 12254330314479522449 and 12254330325892256918).
#[test]
fn a_robot_calls_the_teammates_it_never_heard_when_its_deadline_falls() {
    let mut h = Harness::new(TWICE, 3);
    h.tick(0, &[("first_done", F)]);
    h.tick_one(1, 100, &[("first_done", T)]);
    let key = waiting_at_first(&h, 1);
    let deadline = |h: &Harness| h.kernels[1].instances.get(&key).map(|i| i.deadline);
    let due = deadline(&h).expect("robot 1 waits at `first`'s barrier");
    assert_eq!(audience(&h, 1), [0], "robot 1 tells its leader only");
    // The deadline falls; robot 1 has heard nobody: it calls both.
    h.tick_one(1, due.as_micros().div_ceil(1000), &[("first_done", T)]);
    assert_eq!(h.kernels[1].stats().timeouts, 0);
    assert_eq!(audience(&h, 1), [0, 2], "robot 1 calls robots 0 and 2");
    let later = deadline(&h).expect("still waiting");
    assert!(later > due, "{later:?} after {due:?}");
    // Still unheard two retries on: it decides without them, once.
    h.tick_one(1, later.as_micros().div_ceil(1000), &[("first_done", T)]);
    assert_eq!(h.kernels[1].stats().timeouts, 1);
}

/// Three robots started on `a` (a barrier `s` below it), then `b`, then
/// `c`, whose successors are `c_next` (`next: [a]`: a cycle), every
/// behavior ending by its own condition.
fn a_b_c(c_next: &str) -> Harness {
    a_b_c_with("team: true", c_next)
}

/// [`a_b_c`] with `c`'s `team` field `c_team`.
fn a_b_c_with(c_team: &str, c_next: &str) -> Harness {
    let graph = format!(
        "start: root
defaults: {{ terminate: term.local }}
behaviors:
  root: {{ team: true, children: [a] }}
  a: {{ team: true, children: [s], until: a_done, next: [b] }}
  b: {{ team: true, skill: w, until: b_done, next: [c] }}
  c: {{ {c_team}, skill: w, until: c_done, {c_next} }}
  s: {{ team: true, skill: w, until: s_done, terminate: term.test-barrier }}"
    );
    let mut h = Harness::new(&graph, 3);
    let off = [("a_done", F), ("b_done", F), ("c_done", F), ("s_done", F)];
    h.tick(0, &off);
    h
}

/// A teammate heard in a later execution of the behavior this robot's
/// execution came after, a behavior whose only successor is this robot's
/// (`c`#2 beside `a`#2, which came after `c`#1), went round past this
/// robot's execution (it ran it, or converged past it): it is marked
/// departed from it and left out of the points below it. Found by
/// `no_waiting_across_levels` (RNG seed 167, graph seed
/// 5857852094645335443): the robot waited at an allocation below `b1`#2
/// for a teammate in `b3`#2, taken for one on its way, until the run
/// stalled.
#[test]
fn a_teammate_gone_round_past_an_execution_is_departed_from_it() {
    let mut h = a_b_c("next: [a]");
    // Robot 1 goes round alone: `a`#1, `b`#1, `c`#1, then `a`#2, and ends
    // `s` there, waiting at its barrier for robots 0 and 2.
    h.tick_one(1, 100, &[("a_done", T)]);
    h.tick_one(1, 200, &[("a_done", F), ("b_done", T)]);
    h.tick_one(1, 300, &[("b_done", F), ("c_done", T)]);
    h.tick_one(1, 400, &[("c_done", F), ("s_done", T)]);
    let g = h.kernels[1].mission().graph().clone();
    let [root, a, b, c, s] = ["root", "a", "b", "c", "s"].map(|n| g.find(n).expect("behavior"));
    let id = |behavior, epoch| FrameId {
        team: TeamId::ROOT,
        behavior,
        epoch,
    };
    assert!(
        h.kernels[1].stack().iter().any(|f| f.id() == id(a, 2)),
        "robot 1 runs `a`#2: {:?}",
        h.stack(1)
    );
    let barrier = barrier_at(&h, 1, s);
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
    // Robot 2 runs `c`#2, after `b`#2: it is past `a`#2.
    let mut past = running(&[(id(root, 1), None), (id(c, 2), Some((id(b, 2), false)))]);
    past.robot = RobotId(2);
    h.kernels[1].peer(Time::from_millis(450), RobotId(2), &past);
    assert_gone_from(
        &h,
        1,
        id(a, 2),
        barrier,
        RobotId(2),
        "robot 2 is past `a`#2",
    );
}

/// A later run of an individual behavior (`team: false`) before this
/// robot's execution is no lap past it: each member numbers its runs of
/// one at its own pace. A teammate in its `c`#2 after `b`#1, beside this
/// robot's `a`#2 after its own `c`#1, is on its way into `a`#2, not gone
/// round past it, and is not marked departed from it. Found by
/// `no_waiting_across_levels` (RNG seed 250, graph seed
/// 2799136479243646113: r3 at `b1`#3's auction, after its `b2`#2, left
/// out r0 in its `b2`#3 of the same lap, and both sides' deadlines fell).
#[test]
fn a_later_run_of_an_individual_behavior_is_no_lap_past() {
    let mut h = a_b_c_with("team: false", "next: [a]");
    // Robot 1 goes round alone, as in the test above.
    h.tick_one(1, 100, &[("a_done", T)]);
    h.tick_one(1, 200, &[("a_done", F), ("b_done", T)]);
    h.tick_one(1, 300, &[("b_done", F), ("c_done", T)]);
    h.tick_one(1, 400, &[("c_done", F), ("s_done", T)]);
    let [root, a, b, c, s] = behaviors(&h, 1, ["root", "a", "b", "c", "s"]);
    let barrier = barrier_at(&h, 1, s);
    // Robot 2 runs `c`#2 (its second run of `c`) after `b`#1.
    let mut lap = running(&[
        (at_root(root, 1), None),
        (at_root(c, 2), Some((at_root(b, 1), false))),
    ]);
    lap.robot = RobotId(2);
    h.kernels[1].peer(Time::from_millis(450), RobotId(2), &lap);
    assert!(
        !departed_from(&h, 1, at_root(a, 2), RobotId(2)),
        "robot 2 is on its way into `a`#2"
    );
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
}

/// A cycle `b`, `c`, `a` under the root, where `a` is an individual
/// behavior (`team: false`) whose child `s` ends at a barrier.
const LAPS: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [b] }
  b: { team: true, skill: w, until: b_done, next: [c] }
  c: { team: true, skill: w, until: c_done, next: [a] }
  a: { team: false, children: [s], until: a_done, next: [b] }
  s: { team: true, skill: w, until: s_done, terminate: term.test-barrier }";

/// Three robots on [`LAPS`], every condition false.
fn laps() -> Harness {
    let mut h = Harness::new(LAPS, 3);
    h.tick(
        0,
        &[("a_done", F), ("b_done", F), ("c_done", F), ("s_done", F)],
    );
    h
}

/// Robot `i` goes once round [`LAPS`] from `b` at `ms` (a tick every
/// 100 ms), and ends with `last` (`a_done`: on to the next `b`; `s_done`:
/// waiting at the barrier under `a`).
fn go_round(h: &mut Harness, i: usize, ms: u64, last: &'static str) {
    h.tick_one(i, ms, &[("a_done", F), ("b_done", T)]);
    h.tick_one(i, ms + 100, &[("b_done", F), ("c_done", T)]);
    h.tick_one(i, ms + 200, &[("c_done", F), (last, T)]);
}

/// Asserts that robot `i` runs execution `id`.
fn assert_runs(h: &Harness, i: usize, id: FrameId) {
    assert!(
        h.kernels[i].stack().iter().any(|f| f.id() == id),
        "robot {i} runs {id:?}: {:?}",
        h.stack(i)
    );
}

/// Robot `to` hears robot `from` at `ms` burn execution `id` (its
/// heartbeat lists it among the executions burned recently).
fn tell_burned(h: &mut Harness, to: usize, from: u32, ms: u64, root: BehaviorId, id: FrameId) {
    let mut pos = running(&[(at_root(root, 1), None)]);
    pos.robot = RobotId(from);
    pos.burned = vec![id];
    h.kernels[to].peer(Time::from_millis(ms), RobotId(from), &pos);
}

/// A teammate in the team execution after this robot's execution of an
/// individual behavior, come from a run of it under an id the team burned,
/// went past this robot's lap: that run was this lap's under a name the
/// team gave up, and its next run will be numbered past it. Beside this
/// robot's `a`#2 (its first, `a`#1 burned), a teammate in `b`#2 after
/// `a`#1 is marked departed from `a`#2 and left out of the points below.
/// Not so when `a`#1 was a lap of the team's (this robot ran it too): the
/// teammate may come round to `a`#2. Found by `no_waiting_across_levels`
/// (RNG seed 1283, graph seed 1510455449266984623: r4 ran `b3`#1 and went
/// on to `b1`#2 while its teammates converged away from `b3`#1 and burned
/// it; r0, at `b3`#2's allocation, waited for r4 until its deadline, twice
/// in the run).
#[test]
fn a_teammate_past_a_burned_lap_of_an_individual_behavior_is_departed_from_it() {
    let mut h = laps();
    let [root, a, b, s] = behaviors(&h, 1, ["root", "a", "b", "s"]);
    // The team burned `a`#1; robot 1 goes round once, to `a`#2, and ends
    // `s` there, waiting at its barrier.
    tell_burned(&mut h, 1, 0, 50, root, at_root(a, 1));
    go_round(&mut h, 1, 100, "s_done");
    assert_runs(&h, 1, at_root(a, 2));
    let barrier = barrier_at(&h, 1, s);
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
    // Robot 2 ran `a`#1 and runs `b`#2 after it.
    let chain = [
        (at_root(root, 1), None),
        (at_root(b, 2), Some((at_root(a, 1), false))),
    ];
    tell(&mut h, 1, 2, Time::from_millis(350), &chain);
    let why = "robot 2, in `b`#2 after the burned `a`#1, is past robot 1's lap of `a`";
    assert_gone_from(&h, 1, at_root(a, 2), barrier, RobotId(2), why);

    // The same, `a`#1 not burned: robot 1 ran it, went round again to
    // `a`#2; robot 2, in `b`#3 after `a`#1, may come round to `a`#2.
    let mut h = laps();
    go_round(&mut h, 1, 100, "a_done");
    go_round(&mut h, 1, 400, "s_done");
    assert_runs(&h, 1, at_root(a, 2));
    let barrier = barrier_at(&h, 1, s);
    let chain = [
        (at_root(root, 1), None),
        (at_root(b, 3), Some((at_root(a, 1), false))),
    ];
    tell(&mut h, 1, 2, Time::from_millis(650), &chain);
    assert!(
        !departed_from(&h, 1, at_root(a, 2), RobotId(2)),
        "robot 2 may come round to `a`#2"
    );
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
}

/// A robot that left an execution its teammates renamed afterwards (they
/// converged on one a later arrival numbered higher, after the same step,
/// and burned the old name) counts past the new name: its next run of the
/// behavior is numbered after it, not with it. Robot 1 ends `a`#1 (after
/// `c`#1) and goes on to `b`#2; the team then burns `a`#1 and a teammate
/// runs `a`#2 after `c`#1, the same step: robot 1's next lap runs `a`#3.
/// Without the burn, `a`#2 after `c`#1 is only the teammate's own count of
/// an individual behavior, and robot 1's next lap runs `a`#2. Found by
/// `no_waiting_across_levels` (RNG seed 377 with the change for seed 1283,
/// graph seed 13085922093764180830: r5 ran `b3`#2 and went on; r2 and r6,
/// still in it, converged on r4's `b3`#3 after the same `b2`#3 and burned
/// `b3`#2; r5 then numbered its next lap `b3`#3, the team's lap before,
/// and the laps crossed until a deadline).
#[test]
fn a_robot_counts_past_a_lap_renamed_after_it_left() {
    let run = |burned: bool, renamed: bool| {
        let mut h = laps();
        let [root, a, b, c] = behaviors(&h, 1, ["root", "a", "b", "c"]);
        go_round(&mut h, 1, 100, "a_done");
        assert_runs(&h, 1, at_root(b, 2));
        if burned {
            tell_burned(&mut h, 1, 0, 320, root, at_root(a, 1));
        }
        if renamed {
            let chain = [
                (at_root(root, 1), None),
                (at_root(a, 2), Some((at_root(c, 1), false))),
            ];
            tell(&mut h, 1, 2, Time::from_millis(350), &chain);
        }
        h.tick_one(1, 400, &[("a_done", F), ("b_done", T)]);
        h.tick_one(1, 500, &[("b_done", F), ("c_done", T)]);
        (h.kernels[1].stack().iter())
            .find(|f| f.behavior == a)
            .map(|f| f.epoch)
    };
    assert_eq!(
        run(false, false),
        Some(2),
        "nothing heard: the next lap is `a`#2"
    );
    assert_eq!(
        run(false, true),
        Some(2),
        "`a`#2 after `c`#1 is the teammate's own count: the next lap is `a`#2"
    );
    assert_eq!(
        run(true, true),
        Some(3),
        "`a`#1 burned, `a`#2 after `c`#1 is its new name: the next lap is `a`#3"
    );
}

/// A teammate heard further on this robot's way, two sequential edges past
/// its execution, in a behavior that never leads back to it (`c`#1 beside
/// `a`#1, with `a` then `b` then `c`), went on beyond this robot's
/// execution: it ran it and ended it by its own condition, and will not
/// come to it again. It is marked departed from it and left out of the
/// points below it, though its heartbeat no longer lists the end (the ends
/// a robot reports are bounded). Found by `no_waiting_across_levels` (RNG
/// seed 1061, graph seed 12562543272125157407): a robot waited out a
/// `term.wait-all` deadline under `b33`#2 for two teammates that had ended
/// it long before and run `b34`#2 into `b35`#2.
#[test]
fn a_teammate_gone_on_beyond_an_execution_is_departed_from_it() {
    let mut h = a_b_c("next: []");
    // Robot 1 ends `s` under `a`#1 and waits at its barrier.
    h.tick_one(1, 100, &[("s_done", T)]);
    let [root, a, b, c, s] = behaviors(&h, 1, ["root", "a", "b", "c", "s"]);
    let barrier = barrier_at(&h, 1, s);
    // Robot 0 runs `b`#1: the direct successor, departed as before.
    robot_1_hears_in(&mut h, 0, 150, root, b, a);
    assert!(
        departed_from(&h, 1, at_root(a, 1), RobotId(0)),
        "robot 0, in `b`#1, is past `a`#1"
    );
    // Robot 2 (not the team's leader, which robot 1 would meet: see
    // `Kernel::meet`) runs `c`#1, after `b`#1, and no longer reports `a`#1
    // ended.
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
    robot_1_hears_in(&mut h, 2, 200, root, c, b);
    let why = "robot 2, in `c`#1, went on beyond `a`#1";
    assert_gone_from(&h, 1, at_root(a, 1), barrier, RobotId(2), why);
}

/// A teammate further on, in a behavior this robot's execution leads to
/// that a way not through it leads to as well (`c`#1 beside `a`#1, with
/// `p` then `a` or `q`, `a` then `b` then `c`, and `q` then `c`), may have
/// come by the other way: it is not departed from this robot's execution.
/// So is one beside an execution on a cycle (property seed 259, graph
/// seed 3518242391574278183: a member that took an individual behavior's
/// other successor, by a precondition that held for it alone, was taken
/// for one gone on beyond its team's execution and left out of it, though
/// it converged back into it a moment later; an allocation split and a
/// synchronization's deadline followed).
#[test]
fn a_teammate_that_may_have_come_another_way_is_not_gone_on_beyond() {
    const OTHER_WAY: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { team: true, skill: w, until: p_done, next: [a, q] }
  a: { team: true, children: [s], pre: want_a, until: a_done, next: [b] }
  b: { team: true, skill: w, until: b_done, next: [c] }
  q: { team: true, skill: w, pre: want_q, until: q_done, next: [c] }
  c: { team: true, skill: w, until: c_done }
  s: { team: true, skill: w, until: s_done, terminate: term.test-barrier }";
    let mut h = Harness::new(OTHER_WAY, 3);
    let off = [
        "p_done", "want_a", "want_q", "a_done", "b_done", "q_done", "c_done", "s_done",
    ];
    h.tick(0, &off.map(|b| (b, F)));
    // Robot 1 takes `a` after `p`#1, ends `s` below it and waits there.
    h.tick_one(1, 100, &[("p_done", T), ("want_a", T)]);
    h.tick_one(1, 200, &[("s_done", T)]);
    let [root, a, q, c, s] = behaviors(&h, 1, ["root", "a", "q", "c", "s"]);
    let barrier = barrier_at(&h, 1, s);
    // Robot 2 runs `c`#1 after `q`#1: it went the other way.
    robot_1_hears_in(&mut h, 2, 250, root, c, q);
    assert!(!departed_from(&h, 1, at_root(a, 1), RobotId(2)));
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
}

/// A teammate in a later execution of this robot's own behavior, come
/// there another way, will not come to this robot's execution: it is
/// departed from it and left out of the points below. Before, a robot a
/// lap behind waited at a point below for a teammate that had converged
/// past it onto the team's next lap, until its deadline (found by
/// `no_waiting_across_levels`, RNG seed 6239, graph seed
/// 11787103274286648411: r5, in `b31`#1 after `b30`#1, waited out its
/// `alloc.auction`'s deadline below for r4, which converged from `b30`#1
/// onto `b31`#2 after `alt32`#1).
#[test]
fn a_teammate_a_lap_ahead_come_another_way_is_gone_from_this_lap() {
    const LAP: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { team: true, skill: w, until: p_done, next: [a, q] }
  q: { team: true, skill: w, pre: want_q, until: q_done, next: [a] }
  a: { team: true, children: [s], pre: want_a, until: a_done, next: [p] }
  s: { team: true, skill: w, until: s_done, terminate: term.test-barrier }";
    let mut h = Harness::new(LAP, 3);
    let off = ["p_done", "q_done", "a_done", "s_done", "want_a", "want_q"];
    h.tick(0, &off.map(|b| (b, F)));
    // Robot 1 takes `a`#1 after `p`#1, ends `s` below it and waits there.
    h.tick_one(1, 100, &[("p_done", T), ("want_a", T)]);
    h.tick_one(1, 200, &[("s_done", T)]);
    let [root, q, a, s] = behaviors(&h, 1, ["root", "q", "a", "s"]);
    let barrier = barrier_at(&h, 1, s);
    assert!(!departed_from(&h, 1, at_root(a, 1), RobotId(2)));
    // Robot 2 runs `a`#2 after `q`#1: the team's next lap, come by `q`.
    let chain = [
        (at_root(root, 1), None),
        (at_root(a, 2), Some((at_root(q, 1), false))),
    ];
    tell(&mut h, 1, 2, Time::from_millis(250), &chain);
    assert_eq!(h.stack(1), ["root", "a"], "robot 1 stays in its lap");
    assert_gone_from(
        &h,
        1,
        at_root(a, 1),
        barrier,
        RobotId(2),
        "robot 2 is a lap ahead",
    );
}

/// A team whose members choose `b` or `c` after `a` each by its own
/// preconditions (one option each: no protocol runs), and go on from
/// either to `d`.
const CHOOSE: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: true, skill: w, until: a_done, next: [b, c] }
  b: { team: true, skill: w, pre: want_b, until: b_done, next: [d] }
  c: { team: true, skill: w, pre: want_c, until: c_done, next: [d] }
  d: { team: true, skill: w, until: d_done }";

const CHOOSE_OFF: [(&str, Value); 6] = [
    ("a_done", F),
    ("b_done", F),
    ("c_done", F),
    ("d_done", F),
    ("want_b", F),
    ("want_c", F),
];

/// `robots` robots on [`CHOOSE`], heard by each other at the start; then
/// robot `on_b` takes `b` after `a`#1 and robot `on_c` takes `c`, each
/// alone, while the others stay in `a`.
fn chosen_apart(robots: usize, on_b: usize, on_c: usize) -> Harness {
    let mut h = Harness::new(CHOOSE, robots);
    h.tick(0, &CHOOSE_OFF);
    h.heartbeats();
    h.tick_one(on_b, 100, &[("a_done", T), ("want_b", T)]);
    h.tick_one(on_c, 100, &[("a_done", T), ("want_c", T)]);
    assert_eq!(h.stack(on_b), ["root", "b"]);
    assert_eq!(h.stack(on_c), ["root", "c"]);
    h
}

/// Members that went on past their leader and chose apart at a point with
/// several successors hear each other: the lowest-id one relays the
/// team's heartbeats while the leader is behind on its way, at work as
/// well as at a point, and the split heals. Before, each sent its
/// heartbeats to the leader alone and the split stayed unseen until the
/// leader came (found by `no_waiting_across_levels`, graph seed
/// 15725357882910428641: r1 and r5 ran `alt4` and `b2` side by side for
/// 6.5 s, breaking `splits-healed`).
#[test]
fn members_ahead_of_their_leader_that_chose_apart_hear_each_other() {
    let mut h = chosen_apart(3, 1, 2);
    assert_eq!(h.stack(0), ["root", "a"], "r0, the leader, is behind");
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0, 2], "r1 relays while r0 is in `a`");
    assert_eq!(audience(&h, 2), [0, 1], "r2 sends to r1 too");
    h.heartbeats();
    assert_eq!(h.stack(2), ["root", "b"], "r2 follows r1, the lower id");
    // Once the leader comes, the members send to it alone again.
    h.tick_one(0, 200, &[("a_done", T), ("want_b", T)]);
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0]);
}

/// The same with a member behind as well as the leader: the members past
/// the point take it, unheard, for the one that relays, and it answers
/// them, so that they learn it is behind and find the lowest of
/// themselves. Before, the member behind heard them and said nothing; the
/// two that chose apart sent their heartbeats to it and to the leader,
/// both behind, and ran their two successors side by side until the
/// leader came (found by `no_waiting_across_levels`, RNG seed 3859, graph
/// seed 5905993687803114408: r3 and r5 ran `alt19` and `b3` for 5.8 s,
/// breaking `splits-healed`; the leader, r0, and r1 and r2 were still in
/// `b2`).
#[test]
fn members_past_a_split_find_each_other_past_members_behind() {
    let mut h = chosen_apart(4, 2, 3);
    assert_eq!(h.stack(1), ["root", "a"], "r1 is behind");
    assert_eq!(h.stack(0), ["root", "a"], "and r0, the leader");
    h.heartbeats();
    assert_eq!(audience(&h, 3), [0, 1], "r3 takes r1 for the relay");
    assert_eq!(audience(&h, 1), [0]);
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0, 2, 3], "r1 answers those past it");
    h.heartbeats();
    assert_eq!(audience(&h, 2), [0, 1, 3], "r2 relays, r1 being behind");
    h.heartbeats();
    assert_eq!(h.stack(3), ["root", "b"], "r3 follows r2, the lower id");
    // Once r1 comes, it relays, the lowest member past the point; once
    // the leader comes, the members send to it alone again.
    h.tick_one(1, 200, &[("a_done", T), ("want_b", T)]);
    h.heartbeats();
    h.heartbeats();
    assert_eq!(audience(&h, 1), [0, 2, 3]);
    assert_eq!(audience(&h, 2), [0, 1]);
    h.tick_one(0, 300, &[("a_done", T), ("want_b", T)]);
    h.heartbeats();
    h.heartbeats();
    for r in 1..4 {
        assert_eq!(audience(&h, r), [0]);
    }
    assert!(h.kernels[1].answering.is_none());
}

/// A teammate that ended the execution this robot's execution came after
/// and went through another successor of it, ahead of this robot: the
/// split is seen from the executions the teammate ended, and this robot
/// follows it there (the healing leader's choice). Before, only a
/// teammate's running frames were compared: a member whose teammates had
/// already ended the other side passed it at once on their releases, was
/// never heard in it, and the robot waited on its own side for teammates
/// gone on, at every point a deadline (found by `no_waiting_across_levels`,
/// graph seed 5063174684227258361).
#[test]
fn a_split_the_other_side_went_through_is_seen_and_healed() {
    // `d` individual, as `b1` in that graph: the two histories are not
    // compared as diverged ones (`Kernel::meet`).
    let start = || {
        let mut h = Harness::new(&CHOOSE.replace("d: { team: true", "d: { team: false"), 2);
        h.tick(0, &CHOOSE_OFF);
        h.tick_one(1, 100, &[("a_done", T), ("want_c", T)]);
        assert_eq!(h.stack(1), ["root", "c"]);
        let g = h.kernels[1].mission().graph().clone();
        let [root, a, b, d] = ["root", "a", "b", "d"].map(|n| g.find(n).expect("behavior"));
        let id = |behavior, epoch| FrameId {
            team: TeamId::ROOT,
            behavior,
            epoch,
        };
        // Robot 0 ran `b`#1 after `a`#1 and is in `d`#1 already, which it
        // runs alone.
        let mut theirs = running(&[(id(root, 1), None), (id(d, 1), Some((id(b, 1), false)))]);
        theirs.robot = RobotId(0);
        theirs.ended = ends_under_root(root, &[(a, 1), (b, 1)]);
        (h, theirs, id(b, 1))
    };
    // Ended, but burned (it converged away from it): not followed.
    let (mut h, mut burned, b1) = start();
    burned.burned = vec![b1];
    h.kernels[1].peer(Time::from_millis(150), RobotId(0), &burned);
    assert_eq!(h.stack(1), ["root", "c"]);
    let (mut h, theirs, _) = start();
    h.kernels[1].peer(Time::from_millis(150), RobotId(0), &theirs);
    h.drain(1);
    assert_eq!(
        h.stack(1),
        ["root", "b"],
        "robot 1 follows robot 0 into `b`"
    );
    assert!(
        h.events_of(1).into_iter().any(
            |e| matches!(e, Event::Split { follows: true, member, .. } if *member == RobotId(0))
        ),
        "and says it followed"
    );
}

/// A robot that follows a teammate through the executions it ended into
/// the other side of a split counts past the team executions the teammate
/// ended before the one it follows, not those it ended after: those come
/// after it, on the way the robot now takes, and the robot joins them.
/// Counted past, the robot numbered its next one apart from the team's and
/// waited in it while the team, past it, waited for the robot at the next
/// point (found by `no_waiting_across_levels`, RNG seed 8310, graph seed
/// 15285885989656780006: r5 followed r0 into `alt4`#2, counted past `b3`#2,
/// which came after it, ran `b3`#3 instead, and r0 waited for it at `b1`#3's
/// allocation until its deadline).
#[test]
fn a_robot_following_a_teammate_through_its_ends_joins_what_came_after() {
    let graph = CHOOSE.replace(
        "d: { team: true, skill: w, until: d_done }",
        "d: { team: true, skill: w, until: d_done, next: [e] }\n  e: { team: false, skill: w }",
    );
    let mut h = Harness::new(&graph, 2);
    h.tick(0, &CHOOSE_OFF);
    h.tick_one(1, 100, &[("a_done", T), ("want_c", T)]);
    assert_eq!(h.stack(1), ["root", "c"]);
    let [root, a, b, d, e] = behaviors(&h, 1, ["root", "a", "b", "d", "e"]);
    // Robot 0 ran `a`#1, `b`#1 and `d`#1, and runs `e`#1.
    let mut theirs = running(&[
        (at_root(root, 1), None),
        (at_root(e, 1), Some((at_root(d, 1), false))),
    ]);
    theirs.robot = RobotId(0);
    theirs.ended = ends_under_root(root, &[(a, 1), (b, 1), (d, 1)]);
    h.kernels[1].peer(Time::from_millis(150), RobotId(0), &theirs);
    h.drain(1);
    assert_eq!(h.stack(1), ["root", "b"], "robot 1 follows robot 0");
    assert_eq!(h.kernels[1].org.runs(TeamId::ROOT, d), 0, "`d`#1 is next");
    h.tick_one(1, 200, &[("b_done", T)]);
    let epoch = (h.kernels[1].stack().iter()).find(|f| f.behavior == d);
    assert_eq!(epoch.map(|f| f.epoch), Some(1), "{:?}", h.stack(1));
}

/// The same split when the other side is an individual behavior that the
/// teammate has run more often than this robot (each numbers its runs of
/// it at its own pace: this robot missed a lap of it): the teammate's
/// order tells which of its executions came right after the point, not
/// the epoch this robot would give it. Before, only the epoch after this
/// robot's own count was looked for, and the split went unseen (found by
/// `no_waiting_across_levels`, RNG seed 7540, graph seed
/// 14163924047870139797: r3 missed a lap of the individual `b8` and
/// stayed on `alt16` while r2 waited for it at `b6`'s allocation, two
/// deadlines).
#[test]
fn a_split_onto_an_individual_successor_run_more_often_is_seen() {
    let graph = CHOOSE
        .replace("d: { team: true", "d: { team: false")
        .replace("b: { team: true", "b: { team: false");
    let start = |order: [&str; 2]| {
        let mut h = Harness::new(&graph, 2);
        h.tick(0, &CHOOSE_OFF);
        h.tick_one(1, 100, &[("a_done", T), ("want_c", T)]);
        assert_eq!(h.stack(1), ["root", "c"]);
        let g = h.kernels[1].mission().graph().clone();
        let [root, a, b, d] = ["root", "a", "b", "d"].map(|n| g.find(n).expect("behavior"));
        // Robot 0 ran its second `b` after `a`#1 and is in `d`#1.
        let mut theirs = running(&[
            (at_root(root, 1), None),
            (at_root(d, 1), Some((at_root(b, 2), false))),
        ]);
        theirs.robot = RobotId(0);
        theirs.ended = order
            .map(|x| position::Ended {
                id: if x == "a" {
                    at_root(a, 1)
                } else {
                    at_root(b, 2)
                },
                parent: Some(at_root(root, 1)),
            })
            .to_vec();
        h.kernels[1].peer(Time::from_millis(150), RobotId(0), &theirs);
        h.drain(1);
        h
    };
    let h = start(["a", "b"]);
    assert_eq!(
        h.stack(1),
        ["root", "b"],
        "robot 1 follows robot 0 into `b`"
    );
    // A run of `b` it ended before `a`#1 came before the point: not the
    // other side of it.
    let h = start(["b", "a"]);
    assert_eq!(h.stack(1), ["root", "c"]);
}

/// A cycle `a`, `d`, `e` under the root; `a` a team behavior or an
/// individual one.
fn cycle(a_is_team: bool) -> String {
    format!(
        "start: root
defaults: {{ terminate: term.local }}
behaviors:
  root: {{ team: true, children: [a] }}
  a: {{ team: {a_is_team}, skill: w, until: a_done, next: [d] }}
  d: {{ team: true, skill: w, until: d_done, next: [e] }}
  e: {{ team: true, skill: w, until: e_done, next: [a] }}"
    )
}

/// Robot 0's heartbeat in [`cycle`]: in `d`#2 after `a`#`after`, under the
/// root's first execution, telling the executions `ended` there.
fn robot_0_in_d2(
    [root, a, d]: [BehaviorId; 3],
    after: u32,
    ended: &[(BehaviorId, u32)],
) -> Position {
    let mut theirs = running(&[
        (at_root(root, 1), None),
        (at_root(d, 2), Some((at_root(a, after), false))),
    ]);
    theirs.robot = RobotId(0);
    theirs.ended = ends_under_root(root, ended);
    theirs
}

/// A position's ended executions `ends` (behavior, epoch) of the root
/// team, oldest first, each under the root's first execution.
fn ends_under_root(root: BehaviorId, ends: &[(BehaviorId, u32)]) -> Vec<position::Ended> {
    (ends.iter())
        .map(|&(b, n)| position::Ended {
            id: at_root(b, n),
            parent: Some(at_root(root, 1)),
        })
        .collect()
}

/// A robot that follows a teammate into another execution after the same
/// predecessor takes on the teammate's count of the team behaviors it ended
/// under the parent: the two then number their next executions of those
/// behaviors alike. Not of the execution it joins (the teammate may have
/// ended it and wait at its termination), nor of an individual behavior
/// (each member numbers its runs of one at its own pace). Before, a robot
/// that had run a behavior of the loop fewer times numbered its next run
/// of it one lower, and a barrier after it took the teammate on its way
/// there for one gone round past (found by `no_waiting_across_levels`,
/// graph seed 13366699504392707480: r2 waited out an allocation's deadline
/// for r1, its coordinator, in its `alt4`#4 on the way, r2 having run that
/// lap as `alt4`#3).
#[test]
fn a_robot_that_follows_a_teammate_counts_the_team_behaviors_it_ended() {
    let mut h = Harness::new(&cycle(false), 2);
    h.tick(0, &[("a_done", F), ("d_done", F), ("e_done", F)]);
    h.tick_one(1, 100, &[("a_done", T)]);
    h.tick_one(1, 200, &[("a_done", F)]);
    assert_eq!(h.stack(1), ["root", "d"]);
    let [root, a, d, e] = behaviors(&h, 1, ["root", "a", "d", "e"]);
    // Robot 0, its own first run of `a` behind it too, is in `d`#2: it ran
    // `d`#1 and `e`#1 (and a later run of `a`), and has ended `d`#2 too.
    let theirs = robot_0_in_d2([root, a, d], 1, &[(d, 1), (e, 1), (a, 3), (d, 2)]);
    h.kernels[1].peer(Time::from_millis(250), RobotId(0), &theirs);
    h.drain(1);
    assert_eq!(h.selected_via(1, "d"), [Via::Sequence, Via::Converged]);
    let top = |h: &Harness| h.kernels[1].stack().last().map(|f| f.id());
    assert_eq!(
        top(&h),
        Some(at_root(d, 2)),
        "robot 1 joins `d`#2, not a later one"
    );
    assert_eq!(h.kernels[1].org.runs(TeamId::ROOT, e), 1, "`e`#1 is past");
    assert_eq!(
        h.kernels[1].org.runs(TeamId::ROOT, a),
        1,
        "`a` counted at its own pace"
    );
    h.tick_one(1, 300, &[("d_done", T)]);
    assert_eq!(top(&h), Some(at_root(e, 2)), "the team's next `e`");
}

/// A robot a lap behind that converges onto a teammate's execution comes
/// after the teammate's predecessor, an execution it never ran: that
/// execution is behind its way now, as one it ran is (`Kernel::passed`),
/// so a teammate still in it is on its way to this robot. Found by
/// `no_waiting_across_levels`, RNG seed 7621 (graph seed
/// 7437662065035196631): r3, in `b1`#1, converged onto `b2`#2 after
/// `b1`#2, and at `b3`#2's allocation took r4, still in `b1`#2, for a
/// teammate elsewhere; its deadline decided without it.
#[test]
fn a_robot_that_converged_past_an_execution_takes_a_teammate_in_it_for_one_behind() {
    let mut h = Harness::new(&cycle(true), 3);
    h.tick(0, &[("a_done", F), ("d_done", F), ("e_done", F)]);
    assert_eq!(h.stack(1), ["root", "a"]);
    let [root, a, d, e] = behaviors(&h, 1, ["root", "a", "d", "e"]);
    // Robot 0 went round: `a`#1, `d`#1, `e`#1, `a`#2, and runs `d`#2.
    // The ends it tells are the last few (`RECENT`): not `a`#1.
    let theirs = robot_0_in_d2([root, a, d], 2, &[(d, 1), (e, 1), (a, 2)]);
    h.kernels[1].peer(Time::from_millis(250), RobotId(0), &theirs);
    h.drain(1);
    assert_eq!(
        h.kernels[1].stack().last().map(|f| f.id()),
        Some(at_root(d, 2)),
        "robot 1 converged onto `d`#2"
    );
    let k = &h.kernels[1];
    assert!(
        k.passed(1, at_root(root, 1), at_root(a, 2)),
        "`a`#2, which `d`#2 came after, is behind robot 1's way"
    );
    assert!(
        !k.passed(1, at_root(root, 1), at_root(a, 3)),
        "`a`#3 is not"
    );
    assert_eq!(k.org.runs(TeamId::ROOT, a), 2, "the team's count of `a`");
    // Robot 2 waits at the end of `a`#2 for the team, robot 1 among it:
    // robot 1 answers it (its heartbeats tell it went past), as it does a
    // teammate waiting below an execution it ended. Before, it answered
    // it only because it took `a`#2 for an execution it had yet to start.
    let mut waiting = running(&[
        (at_root(root, 1), None),
        (at_root(a, 2), Some((at_root(e, 1), false))),
    ]);
    waiting.robot = RobotId(2);
    if let Some(f) = waiting.frames.last_mut() {
        f.state = FrameState::Ending;
    }
    h.kernels[1].peer(Time::from_millis(300), RobotId(2), &waiting);
    assert!(
        (h.kernels[1].answering.as_ref()).is_some_and(|a| a.contains(RobotId(2))),
        "robot 1 answers a teammate waiting below an execution it went past"
    );
}

/// The healing leader at a point waits for a teammate it saw on the other
/// side of a split: the teammate took another successor after the same
/// execution and follows the leader's side within a heartbeat, so it is on
/// its way. Before, it was neither behind nor at the point, and the
/// leader's deadline fell between seeing the split and the teammate's
/// arrival (found by `no_waiting_across_levels`, RNG seed 2164, graph
/// seed 541206029754869826: r1's auction deadline fell 75 ms after it saw
/// r2 in `alt8` and 60 ms before r2 joined `b6`).
#[test]
fn the_healing_leader_waits_for_a_teammate_on_the_other_side_of_a_split() {
    let graph = CHOOSE.replace(
        "next: [d] }\n  c:",
        "next: [d], terminate: term.test-barrier }\n  c:",
    );
    let mut h = Harness::new(&graph, 2);
    h.tick(0, &CHOOSE_OFF);
    h.tick_one(0, 100, &[("a_done", T), ("want_b", T)]);
    h.tick_one(0, 200, &[("a_done", F), ("b_done", T)]);
    let [root, a, b, c] = behaviors(&h, 0, ["root", "a", "b", "c"]);
    let key = barrier_at(&h, 0, b);
    // Robot 1 at work in `a`#1: behind, awaited.
    tell(
        &mut h,
        0,
        1,
        Time::from_millis(250),
        &[
            (at_root(root, 1), None),
            (at_root(a, 1), Some((at_root(root, 1), true))),
        ],
    );
    assert!(h.kernels[0].awaited_at_work(key));
    // Then in `c`#1, after `a`#1: robot 0, the healing leader, keeps its
    // side, and robot 1 comes over.
    tell(
        &mut h,
        0,
        1,
        Time::from_millis(300),
        &[
            (at_root(root, 1), None),
            (at_root(c, 1), Some((at_root(a, 1), false))),
        ],
    );
    h.drain(0);
    assert_eq!(h.stack(0), ["root"], "robot 0 still waits at `b`'s end");
    assert!(
        h.events_of(0).into_iter().any(
            |e| matches!(e, Event::Split { follows: false, member, .. } if *member == RobotId(1))
        ),
        "robot 0 saw the split"
    );
    assert!(
        h.kernels[0].awaited_at_work(key),
        "robot 1 is on its way from the other side"
    );
}

/// Two robots lapping `a`, `d` under the root (`d` a team behavior or an
/// individual one): robot 1 has ended `a`#1 and runs `d`.
fn lapping(d_is_team: bool) -> (Harness, [BehaviorId; 3]) {
    let graph = format!(
        "start: root
defaults: {{ terminate: term.local }}
behaviors:
  root: {{ team: true, children: [a] }}
  a: {{ team: true, skill: w, until: a_done, next: [d] }}
  d: {{ team: {d_is_team}, skill: w, until: d_done, next: [a] }}"
    );
    let mut h = Harness::new(&graph, 2);
    h.tick(0, &[("a_done", F), ("d_done", F)]);
    h.tick_one(1, 100, &[("a_done", T)]);
    h.tick_one(1, 200, &[("a_done", F)]);
    assert_eq!(h.stack(1), ["root", "d"]);
    let g = h.kernels[1].mission().graph().clone();
    let ids = ["root", "a", "d"].map(|n| g.find(n).expect("behavior"));
    (h, ids)
}

/// A lap of an individual behavior (`team: false`) is numbered by each
/// member at its own pace: a teammate in the same execution id of it,
/// after a later execution of the team behavior before it, ran another
/// lap, not this one. Before, `catch_up` took it for the same execution
/// reached by a history that ran the predecessor more times, and burned
/// the predecessor's next execution: the robot, a lap behind, then
/// numbered its next run of the predecessor past the one the team had
/// run and ended, and waited alone at its barrier until the deadline
/// (found by `no_waiting_across_levels`, graph seed 5046127393119846478:
/// r2 alone at `b2`#4's `term.majority`, the team done with `b2`#3).
#[test]
fn a_teammate_a_lap_ahead_in_an_individual_behavior_burns_nothing() {
    let (mut h, [root, a, d]) = lapping(false);
    let id = at_root;
    assert_eq!(h.kernels[1].org.runs(TeamId::ROOT, a), 1);
    // Robot 0 is in its first lap of `d` too, but after `a`#2.
    tell(
        &mut h,
        1,
        0,
        Time::from_millis(250),
        &[(id(root, 1), None), (id(d, 1), Some((id(a, 2), false)))],
    );
    h.drain(1);
    assert_eq!(h.stack(1), ["root", "d"]);
    assert_eq!(
        h.kernels[1].org.runs(TeamId::ROOT, a),
        1,
        "`a`#2 is the team's next run of `a`, not one to skip"
    );
}

/// A teammate that claims to have run the predecessor 4,294,967,295
/// times: the robot catches up (its count of the predecessor goes past
/// the claim) by burning only the latest executions. Before, it burned
/// every execution between, asking for 68 GB, and the process aborted:
/// one heartbeat from a faulty or hostile member (it carries the team's
/// key) took a robot down (found by a network audit, 2026-12-07).
#[test]
fn a_teammate_claiming_an_enormous_epoch_burns_a_bounded_few() {
    let (mut h, [root, a, d]) = lapping(true);
    let id = at_root;
    tell(
        &mut h,
        1,
        0,
        Time::from_millis(250),
        &[
            (id(root, 1), None),
            (id(d, 1), Some((id(a, u32::MAX), false))),
        ],
    );
    h.drain(1);
    assert_eq!(h.kernels[1].org.runs(TeamId::ROOT, a), u32::MAX);
    assert!(h.kernels[1].recent_burned.contains(&id(a, u32::MAX)));
}

/// A robot at a barrier waits for a teammate heard at work in a run of an
/// individual behavior (`team: false`) two sequential edges before its
/// own, whatever epoch the teammate gave that run: each member numbers
/// its runs of an individual behavior at its own pace, so the epoch says
/// nothing of whether the teammate is behind ([`Kernel::passed`]), and
/// its way leads into this robot's execution. Before, only a behavior
/// followed directly by this robot's counted: found by
/// `no_waiting_across_levels` (graph seed 10264868072022678513: r2 in
/// `b3`#3, after `b2`#3 after its `b1`#2, waited out the auction's
/// deadline for r3, still in its `b1`#3 on the way to `b2`#3).
#[test]
fn a_teammate_in_an_individual_behavior_two_edges_back_is_on_its_way() {
    const WAY: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [a] }
  a: { team: false, skill: w, until: step, next: [b] }
  b: { team: true, skill: w, until: step, next: [c] }
  c: { team: true, skill: w, until: step, terminate: term.test-barrier }";
    let (mut h, n, key) = alone_to_the_barrier(WAY, "c");
    let g = h.kernels[0].mission().graph();
    let [root, a, b] = ["root", "a", "b"].map(|n| g.find(n).expect("behavior"));
    let id = at_root;
    let now = |k: u64| Time::from_millis(100 * n + 100 * k);
    // Robot 1 at work in its second run of `a` (robot 0 ran `a` once).
    tell(
        &mut h,
        0,
        1,
        now(1),
        &[(id(root, 1), None), (id(a, 2), Some((id(root, 1), true)))],
    );
    assert!(
        h.kernels[0].awaited_at_work(key),
        "a teammate in an individual behavior leading into c is awaited"
    );
    // In an execution of `b` robot 0 never started: not on its way.
    let beyond = [(id(root, 1), None), (id(b, 40), Some((id(a, 40), false)))];
    tell(&mut h, 0, 1, now(2), &beyond);
    assert!(!h.kernels[0].awaited_at_work(key), "not behind: {beyond:?}");
}

/// A leader at a barrier waits for a member heard at work in a team
/// behavior two sequential edges before the barrier's, on the other
/// successor of a point both went through, which the leader never ran:
/// slow, not silent, it is on its way. Before, only a behavior followed
/// directly by the leader's counted (found by `no_waiting_across_levels`,
/// RNG seed 6286, graph seed 7004174605040164135: r3 at `b5`#2's auction,
/// come through `alt8`#1 and `b7`#1, waited out its deadline for r2, its
/// coordinator, slow in `b5`#1's subtree and then in `b6`#1, on its way
/// through `b7`#1; the same rule serves a member waiting on its leader).
#[test]
fn a_teammate_on_the_other_way_two_edges_back_is_on_its_way() {
    const TWO_WAYS: &str = "start: root
defaults: { terminate: term.local }
behaviors:
  root: { team: true, children: [p] }
  p: { team: true, skill: w, until: p_done, next: [b, c] }
  b: { team: true, skill: w, pre: want_b, until: b_done, next: [e] }
  c: { team: true, skill: w, pre: want_c, until: c_done, next: [e] }
  e: { team: true, skill: w, until: e_done, next: [q] }
  q: { team: true, skill: w, until: q_done, terminate: term.test-barrier }";
    let mut h = Harness::new(TWO_WAYS, 2);
    let off = [
        "p_done", "b_done", "c_done", "e_done", "q_done", "want_b", "want_c",
    ];
    h.tick(0, &off.map(|b| (b, F)));
    h.tick_one(0, 100, &[("p_done", T), ("want_b", T)]);
    h.tick_one(0, 200, &[("p_done", F), ("b_done", T)]);
    h.tick_one(0, 300, &[("b_done", F), ("e_done", T)]);
    h.tick_one(0, 400, &[("e_done", F), ("q_done", T)]);
    let [root, p, c, q] = behaviors(&h, 0, ["root", "p", "c", "q"]);
    let key = barrier_at(&h, 0, q);
    // Robot 1 at work in `c`#1, after `p`#1.
    let chain = [
        (at_root(root, 1), None),
        (at_root(c, 1), Some((at_root(p, 1), false))),
    ];
    tell(&mut h, 0, 1, Time::from_millis(450), &chain);
    assert_eq!(h.stack(0), ["root"], "robot 0 still waits at `q`'s end");
    assert!(
        h.kernels[0].awaited_at_work(key),
        "robot 1 is on its way through `e`"
    );
}

/// A robot at work in an execution whose point a teammate waits at
/// answers the teammate while the leader it sends to there is not heard:
/// the two counted different teammates departed above (an individual
/// behavior ended for the team's lowest ids, each heard by only some of
/// the others), the teammate sends to this robot as its leader, and this
/// robot's heartbeats go to one gone elsewhere. Found by
/// `no_waiting_across_levels` (graph seed 5507922443524571597: r6 and
/// r7, at `b4`#3's synchronization, waited out its deadline for r4 and
/// r5 at work below `b4`#3, whose heartbeats went to r1, gone on to
/// `b2`#3). While the leader is heard, nothing more is sent.
#[test]
fn a_robot_at_work_answers_a_teammate_at_the_point_while_its_leader_is_unheard() {
    let [root, first, _, s] = twice_ids(&twice_of_three());
    let at_the_end = |r: u32| {
        let mut p = running(&[(root, None), (first, Some((root, true)))]);
        p.robot = RobotId(r);
        if let Some(f) = p.frames.last_mut() {
            f.state = FrameState::Ended;
        }
        p
    };
    let answers = |h: &Harness, r: u32| {
        (h.kernels[1].answering.as_ref()).is_some_and(|a| a.contains(RobotId(r)))
    };
    // Robot 1, at work in `s` under `first`, has not heard robot 0, its
    // leader there.
    let mut h = twice_of_three();
    assert_eq!(h.stack(1), ["root", "first", "s"]);
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &at_the_end(2));
    assert!(answers(&h, 2), "{:?}", audience(&h, 1));
    assert!(audience(&h, 1).contains(&2), "{:?}", audience(&h, 1));
    // Its leader heard at work beside it: robot 2 hears robot 0, and robot
    // 1 answers nobody.
    let mut h = twice_of_three();
    tell(
        &mut h,
        1,
        0,
        Time::from_millis(150),
        &[
            (root, None),
            (first, Some((root, true))),
            (s, Some((first, true))),
        ],
    );
    h.kernels[1].peer(Time::from_millis(200), RobotId(2), &at_the_end(2));
    assert!(!answers(&h, 2), "{:?}", audience(&h, 1));
}

/// Execution `epoch` of `behavior` by the root team.
fn at_root(behavior: BehaviorId, epoch: u32) -> FrameId {
    FrameId {
        team: TeamId::ROOT,
        behavior,
        epoch,
    }
}

/// The termination of the root team's first execution of `behavior`.
fn first_termination(behavior: BehaviorId) -> InstanceKey {
    InstanceKey {
        team: TeamId::ROOT,
        behavior,
        kind: Kind::Terminate,
        epoch: 1,
        round: 0,
    }
}

/// The behaviors named `names` in robot `i`'s graph.
fn behaviors<const N: usize>(h: &Harness, i: usize, names: [&str; N]) -> [BehaviorId; N] {
    let g = h.kernels[i].mission().graph().clone();
    names.map(|n| g.find(n).expect("behavior"))
}

/// Robot 1 hears robot `from` at `ms` running `b`#1 after `after`#1, under
/// the root's first execution.
fn robot_1_hears_in(
    h: &mut Harness,
    from: u32,
    ms: u64,
    root: BehaviorId,
    b: BehaviorId,
    after: BehaviorId,
) {
    let chain = [
        (at_root(root, 1), None),
        (at_root(b, 1), Some((at_root(after, 1), false))),
    ];
    tell(h, 1, from, Time::from_millis(ms), &chain);
}

/// The barrier robot `i` waits at, at the end of `behavior`.
fn barrier_at(h: &Harness, i: usize, behavior: BehaviorId) -> InstanceKey {
    (h.kernels[i].instances.iter())
        .find(|(k, x)| {
            k.behavior == behavior && k.kind == Kind::Terminate && x.state == State::Active
        })
        .map(|(k, _)| k)
        .expect("waits at the barrier")
}

/// True when robot `i`'s protocol instance `key` leaves teammate `r` out.
fn left_out(h: &Harness, i: usize, key: InstanceKey, r: RobotId) -> bool {
    (h.kernels[i].instances.get(&key))
        .and_then(|x| x.excluded.as_ref())
        .is_some_and(|x| x.contains(r))
}

/// Asserts that robot `i` counts teammate `r` departed from its execution
/// `id` (`why`) and leaves it out of the barrier `key` below it.
fn assert_gone_from(h: &Harness, i: usize, id: FrameId, key: InstanceKey, r: RobotId, why: &str) {
    assert!(departed_from(h, i, id, r), "{why}");
    assert!(left_out(h, i, key, r), "{why}, and left out of the barrier");
}

/// True when robot `i` counts teammate `r` departed from its execution `id`.
fn departed_from(h: &Harness, i: usize, id: FrameId, r: RobotId) -> bool {
    (h.kernels[i].stack().iter())
        .find(|f| f.id() == id)
        .and_then(|f| f.departed.as_ref())
        .is_some_and(|d| d.contains(r))
}

/// Three robots under the root run `p`, whose successors are `q` (then
/// `a`, a barrier `s` below it) and `off`, an individual behavior whose own
/// successors are `off_next`; the team takes the first enabled successor
/// (`sync.by-rule`). Robot 1 ends `p` and `q` alone, goes on to `a`#1 and
/// ends `s`, waiting at its barrier. Its key, with the ids of `root`, `p`,
/// `a` and `off`.
fn gone_off(off_next: &str) -> (Harness, InstanceKey, [BehaviorId; 4]) {
    gone_off_as(true, false, off_next)
}

/// [`gone_off`] with `a` and `off` team behaviors or individual ones
/// (`team:` as given).
fn gone_off_as(
    a_team: bool,
    off_team: bool,
    off_next: &str,
) -> (Harness, InstanceKey, [BehaviorId; 4]) {
    let graph = format!(
        "start: root
defaults: {{ terminate: term.local }}
behaviors:
  root: {{ team: true, children: [p] }}
  p: {{ team: true, skill: w, until: p_done, next: [q, off], sync: sync.by-rule }}
  q: {{ team: true, skill: w, until: q_done, next: [a] }}
  a: {{ team: {a_team}, children: [s], until: a_done }}
  off: {{ team: {off_team}, skill: w, until: off_done, {off_next} }}
  s: {{ team: true, skill: w, until: s_done, terminate: term.test-barrier }}"
    );
    let mut h = Harness::new(&graph, 3);
    let off = [
        ("p_done", F),
        ("q_done", F),
        ("a_done", F),
        ("off_done", F),
        ("s_done", F),
    ];
    h.tick(0, &off);
    h.tick_one(1, 100, &[("p_done", T)]);
    h.tick_one(1, 150, &[("p_done", F), ("q_done", T)]);
    h.tick_one(1, 200, &[("q_done", F), ("s_done", T)]);
    let [root, p, a, off, s] = behaviors(&h, 1, ["root", "p", "a", "off", "s"]);
    assert_eq!(h.stack(1), ["root", "a"], "robot 1 ended `s` under `a`#1");
    let barrier = barrier_at(&h, 1, s);
    (h, barrier, [root, p, a, off])
}

/// A teammate's chain in [`gone_off`]: `off`#1 after `p`#1, under the
/// root's first execution.
fn in_off_after(
    root: BehaviorId,
    p: BehaviorId,
    off: BehaviorId,
) -> [(FrameId, Option<(FrameId, bool)>); 2] {
    [
        (at_root(root, 1), None),
        (at_root(off, 1), Some((at_root(p, 1), false))),
    ]
}

/// A teammate that went off another way for good is departed from this
/// robot's execution and left out of its points: beside this robot's
/// `a`#1 (after `q`#1), the team's first member heard in `off`#1 after
/// `p`#1 (which this robot ran before `a`#1), `off` an individual behavior
/// that never leads to `a`; then another member heard there with it. Not a member heard
/// there alone (it may converge on the leader's side elsewhere), nor the
/// leader when `off` leads back to `a`. Found by `no_waiting_across_levels`
/// (RNG seeds 5140 and 4646, graph seeds 5028977122179993407 and
/// 1642720823527748982): a member waited at an allocation for its
/// coordinator, the team's first member, gone off into an individual
/// behavior whose chain ends its parent's, until its deadline.
#[test]
fn a_leader_gone_off_for_good_is_departed_from_the_execution() {
    let (mut h, barrier, [root, p, a, off]) = gone_off("next: []");
    let in_off = in_off_after(root, p, off);
    // Robot 2 alone in `off`: it may still follow the leader elsewhere.
    tell(&mut h, 1, 2, Time::from_millis(250), &in_off);
    assert!(!departed_from(&h, 1, at_root(a, 1), RobotId(2)));
    assert!(!left_out(&h, 1, barrier, RobotId(2)));
    // The leader in `off`: gone for good.
    tell(&mut h, 1, 0, Time::from_millis(300), &in_off);
    let id = at_root(a, 1);
    assert_gone_from(&h, 1, id, barrier, RobotId(0), "robot 0 went off");
    // Robot 2 there with the leader: gone for good too.
    tell(&mut h, 1, 2, Time::from_millis(350), &in_off);
    assert_gone_from(&h, 1, id, barrier, RobotId(2), "robot 2 is with robot 0");
}

/// [`a_leader_gone_off_for_good_is_departed_from_the_execution`], but
/// `off` leads back to `a`: the leader may come to `a`#1 yet.
#[test]
fn a_leader_gone_off_a_way_back_is_not_departed() {
    let (mut h, barrier, [root, p, a, off]) = gone_off("next: [a]");
    let in_off = in_off_after(root, p, off);
    tell(&mut h, 1, 0, Time::from_millis(300), &in_off);
    assert!(!departed_from(&h, 1, at_root(a, 1), RobotId(0)));
    assert!(!left_out(&h, 1, barrier, RobotId(0)));
}

/// [`a_leader_gone_off_for_good_is_departed_from_the_execution`] with the
/// roles of team and individual behavior swapped: `a` individual (each
/// member ends it alone) and `off` a team behavior that never leads back
/// to it. The leader in `off` is gone for good as well: it follows no other
/// side at a split, and histories meet only through team behaviors
/// (`Kernel::meet`), so nothing brings it into `a`. With `a` a team
/// behavior too, the histories may still meet, and nobody is departed.
/// Found by `no_waiting_across_levels` (RNG seed 6404, graph seed
/// 859933712933106335): a member waited at an individual behavior's
/// auction for its coordinator, gone into a team behavior that ends the
/// root's chain, until its deadline (docs/reliability.md, "A leader gone
/// off from an individual behavior").
#[test]
fn a_leader_gone_off_into_a_team_behavior_leaves_an_individual_execution() {
    let (mut h, barrier, [root, p, a, off]) = gone_off_as(false, true, "next: []");
    let in_off = in_off_after(root, p, off);
    tell(&mut h, 1, 0, Time::from_millis(300), &in_off);
    assert_gone_from(
        &h,
        1,
        at_root(a, 1),
        barrier,
        RobotId(0),
        "robot 0 went off",
    );
    let (mut h, barrier, [root, p, a, off]) = gone_off_as(true, true, "next: []");
    let in_off = in_off_after(root, p, off);
    tell(&mut h, 1, 0, Time::from_millis(300), &in_off);
    assert!(!departed_from(&h, 1, at_root(a, 1), RobotId(0)));
    assert!(!left_out(&h, 1, barrier, RobotId(0)));
}

/// An instance fits the allocator's 320-byte size class (a large team's
/// robots hold about six each; the next class is 384 bytes), and a
/// binding's durations keep their nanoseconds.
#[test]
fn an_instance_fits_a_320_byte_block_and_keeps_its_durations() {
    assert!(std::mem::size_of::<Instance>() <= 320);
    for d in [
        Duration::ZERO,
        Duration::from_nanos(1),
        Duration::from_micros(1_500),
        Duration::from_secs(30),
        Duration::from_secs(86_400 * 365 * 500),
    ] {
        assert_eq!(PackedDuration::from(d).get(), d);
    }
    let far = PackedDuration::from(Duration::MAX).get();
    assert_eq!(far, Duration::from_nanos(u64::MAX));
}

/// A teammate's record fits 128 bytes, so that a robot's first four fill
/// a 512-byte block (the next size class is 640 bytes).
#[test]
fn a_peer_fits_128_bytes() {
    assert!(std::mem::size_of::<position::Peer>() <= 128);
    assert_eq!(position::MaybeTime::default().get(), None);
    assert_eq!(position::MaybeTime::from(Time(7)).get(), Some(Time(7)));
}
