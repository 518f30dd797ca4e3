//! The per-robot `Agent` (what `bite robot` runs in each process), driven
//! by hand with an instant, lossless network: a team of agents completes
//! the same missions as the simulator's runner, and agrees on its decisions.

mod missions;

use bite_agent::agent::{Agent, AgentOutput};
use bite_agent::schema::Sensed;
use bite_core::event::Event;
use bite_core::ids::RobotId;
use bite_core::interaction::Recipients;
use bite_core::time::Time;
use bite_sim::{Scenario, prepare};
use missions::{FORMATION, graph};
use std::collections::BTreeMap;
use std::time::Duration;

const FORMATION_TIMED: &str = include_str!("../../../examples/scenarios/formation.yaml");
const FORMATION_PHYSICS: &str = include_str!("../../../examples/scenarios/formation-physics.yaml");

/// The robots a message from `from` goes to, by index (a team message
/// not back to its sender).
fn targets(to: &Recipients, from: usize) -> Vec<usize> {
    match to {
        Recipients::One(x) => vec![x.index()],
        Recipients::Team(set) => (set.iter().map(|r| r.index()))
            .filter(|x| *x != from)
            .collect(),
    }
}

/// The formation mission on the scenario `text` (read as `file`).
fn formation_on(file: &str, text: &str) -> (Scenario, std::sync::Arc<bite_core::mission::Mission>) {
    let sc = Scenario::load_str(&file.into(), text).unwrap();
    let g = graph("formation.yaml", FORMATION);
    let mission = prepare(&g, &sc, None, &bite_protocols::registry()).unwrap();
    (sc, mission)
}

/// Run a team of agents: control ticks at the scenario's rate, messages
/// delivered at once, kernel timers at their time; in the physical world
/// the simulator's `World` plays the body (observe / actuate), as
/// `bite sim serve` does. Returns each robot's decisions and completion.
fn run_team(
    sc: &Scenario,
    config: Option<usize>,
    crash: Option<(u32, f64)>,
) -> (Vec<Vec<Event>>, Vec<bool>, f64) {
    let g = match config {
        Some(row) => missions::table2().nth(row - 1).unwrap().1,
        None => graph("formation.yaml", FORMATION),
    };
    let mission = prepare(&g, sc, None, &bite_protocols::registry()).unwrap();
    let n = mission.graph().roster().len();
    let mut agents: Vec<Agent> = (0..n as u32)
        .map(|r| Agent::new(mission.clone(), sc, RobotId(r), 1).unwrap())
        .collect();
    let mut world = sc.physics.as_ref().map(|spec| {
        let names: Vec<String> = (0..n as u32)
            .map(|r| mission.graph().roster().name(RobotId(r)))
            .collect();
        bite_sim::physics::World::new(spec.clone(), &names, mission.graph().symbols(), &sc.file, 1)
            .unwrap()
    });
    let mut events: Vec<Vec<Event>> = vec![Vec::new(); n];
    let mut dead = vec![false; n];
    let period = Duration::from_secs_f64(1.0 / sc.control_hz);
    let mut now = Time::ZERO;
    let limit = Time::ZERO + Duration::from_secs(200);
    while now < limit {
        if let Some((who, at)) = crash
            && now.as_secs_f64() >= at
            && !dead[who as usize]
        {
            dead[who as usize] = true;
            // The others' failure detectors notice 2 s later (below).
        }
        if let Some((who, at)) = crash
            && (now.as_secs_f64() - (at + 2.0)).abs() < period.as_secs_f64() / 2.0
        {
            for (i, a) in agents.iter_mut().enumerate() {
                if !dead[i] {
                    a.member_lost(now, RobotId(who));
                }
            }
        }
        if let Some(w) = world.as_mut() {
            w.advance(now, &dead);
        }
        for i in 0..n {
            if dead[i] {
                continue;
            }
            let s: Option<Sensed> = world.as_mut().map(|w| w.observe(i));
            agents[i].tick(now, s.as_ref());
            for t in 0..n {
                if !dead[t] {
                    agents[t].timer(now);
                }
            }
            // Deliver until quiet.
            let mut queue: Vec<(usize, AgentOutput)> = Vec::new();
            for (k, a) in agents.iter_mut().enumerate() {
                while let Some(o) = a.poll() {
                    queue.push((k, o));
                }
            }
            while let Some((from, o)) = queue.pop() {
                match o {
                    AgentOutput::Send { to, envelope, .. } => {
                        for t in targets(&to, from) {
                            if !dead[t] {
                                agents[t].message(now, envelope.clone());
                                while let Some(o) = agents[t].poll() {
                                    queue.push((t, o));
                                }
                            }
                        }
                    }
                    AgentOutput::Inform(_) => {}
                    AgentOutput::Event(e) => events[from].push(e),
                    AgentOutput::Drive(cmd) => {
                        if let Some(w) = world.as_mut() {
                            w.actuate(from, cmd);
                        }
                    }
                }
            }
        }
        if (0..n).all(|i| dead[i] || agents[i].kernel().is_finished()) {
            break;
        }
        now += period;
    }
    let finished = agents.iter().map(|a| a.kernel().is_finished()).collect();
    (events, finished, now.as_secs_f64())
}

/// Every instance decided by two or more robots has one outcome.
fn assert_agreement(events: &[Vec<Event>]) -> usize {
    let mut by: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (r, evs) in events.iter().enumerate() {
        for e in evs {
            if let Event::InteractionDecided {
                instance, outcome, ..
            } = e
            {
                by.entry(format!("{instance:?}"))
                    .or_default()
                    .push(format!("r{r}: {outcome:?}"));
            }
        }
    }
    let mut joint = 0;
    for (k, v) in &by {
        if v.len() > 1 {
            joint += 1;
            let what = |o: &String| o.split_once(": ").map(|x| x.1.to_string());
            assert!(
                v.iter().all(|o| what(o) == what(&v[0])),
                "disagreement on {k}: {v:?}"
            );
        }
    }
    joint
}

#[test]
fn a_team_of_agents_completes_the_timed_formation() {
    let sc = Scenario::load_str(&"formation.yaml".into(), FORMATION_TIMED).unwrap();
    let (events, finished, end) = run_team(&sc, None, None);
    assert!(finished.iter().all(|f| *f), "not finished by {end} s");
    assert!(assert_agreement(&events) >= 5);
}

#[test]
fn a_team_of_agents_drives_the_formation_through_observe_and_actuate() {
    let sc = Scenario::load_str(&"formation-physics.yaml".into(), FORMATION_PHYSICS).unwrap();
    let (events, finished, end) = run_team(&sc, None, None);
    assert!(finished.iter().all(|f| *f), "not finished by {end} s");
    assert!(end > 30.0 && end < 120.0, "{end}");
    assert!(assert_agreement(&events) >= 5);
}

#[test]
fn agents_reallocate_when_a_teammate_is_lost() {
    let sc = Scenario::load_str(&"formation-physics.yaml".into(), FORMATION_PHYSICS).unwrap();
    // Table II row 7: an elected leader decides at A. (Under the default
    // silent rule at A, the survivors can choose differently: each reads
    // `narrow_ahead` from its own view of the formation's reference.)
    let (events, finished, end) = run_team(&sc, Some(7), Some((2, 15.0)));
    assert!(
        finished[0] && finished[1],
        "survivors not finished by {end} s"
    );
    assert_agreement(&events);
}

/// A runtime may drive the body before it carries out the rest of what a
/// tick asked (the simulator does, so that the world steps while the
/// rest goes out): `take_drive` gives the last drive and leaves every
/// other output, in order, to `poll`; `pending` shows them in place.
#[test]
fn the_drive_comes_out_of_a_tick_first_and_the_rest_stays_in_order() {
    let (sc, mission) = formation_on("formation-physics.yaml", FORMATION_PHYSICS);
    let n = mission.graph().roster().len();
    let names: Vec<String> = (0..n as u32)
        .map(|r| mission.graph().roster().name(RobotId(r)))
        .collect();
    let spec = sc.physics.clone().unwrap();
    let mut world =
        bite_sim::physics::World::new(spec, &names, mission.graph().symbols(), &sc.file, 1)
            .unwrap();
    // Two agents fed the same: one polled whole, one drive-first.
    let mut whole = Agent::new(mission.clone(), &sc, RobotId(0), 1).unwrap();
    let mut split = Agent::new(mission.clone(), &sc, RobotId(0), 1).unwrap();
    let describe = |o: &AgentOutput| format!("{o:?}");
    let mut drives = 0;
    for k in 0..20u64 {
        let now = Time::ZERO + Duration::from_millis(100 * k);
        let s = world.observe(0);
        whole.tick(now, Some(&s));
        split.tick(now, Some(&s));
        let all: Vec<AgentOutput> = std::iter::from_fn(|| whole.poll()).collect();
        let pending: Vec<String> = split.pending().map(describe).collect();
        assert_eq!(pending, all.iter().map(describe).collect::<Vec<_>>());
        let drive = split.take_drive();
        let rest: Vec<String> = std::iter::from_fn(|| split.poll())
            .map(|o| describe(&o))
            .collect();
        let last_drive = all.iter().rev().find_map(|o| match o {
            AgentOutput::Drive(c) => Some(*c),
            _ => None,
        });
        assert_eq!(drive, last_drive, "tick {k}: the last drive");
        let others: Vec<String> = (all.iter())
            .filter(|o| !matches!(o, AgentOutput::Drive(_)))
            .map(describe)
            .collect();
        assert_eq!(rest, others, "tick {k}: the rest, in order");
        assert!(split.take_drive().is_none(), "taken once");
        drives += usize::from(drive.is_some());
        if let Some(cmd) = drive {
            world.actuate(0, cmd);
        }
        world.advance(now + Duration::from_millis(100), &vec![false; n]);
    }
    assert!(
        drives > 10,
        "a physical robot drives at its ticks ({drives})"
    );
}

/// The drained output queues (the agent's and its kernel's) keep their
/// room while the mission runs for at most a second after they last gave
/// it back (a robot deciding often does not allocate at every decision),
/// then give it back at the next drain (a large team's robots mostly do
/// not use it between decisions).
#[test]
fn a_drained_output_queue_gives_back_its_room_at_most_once_a_second() {
    let (sc, mission) = formation_on("formation.yaml", FORMATION_TIMED);
    let n = mission.graph().roster().len();
    let mut agents: Vec<Agent> = (0..n as u32)
        .map(|r| Agent::new(mission.clone(), &sc, RobotId(r), 1).unwrap())
        .collect();
    let mut last_given = vec![Time::ZERO; n];
    let (mut kept, mut given_back) = (0, 0);
    // Drain robot `k`, check its room, and hand back what it asked.
    let mut drain = |a: &mut Agent, k: usize, now: Time, queue: &mut Vec<(usize, AgentOutput)>| {
        let before = queue.len();
        queue.extend(std::iter::from_fn(|| a.poll()).map(|o| (k, o)));
        if a.output_room() == 0 {
            last_given[k] = now;
            given_back += usize::from(queue.len() > before);
        } else {
            kept += 1;
            assert!(
                now - last_given[k] < Duration::from_secs(1),
                "{k} kept room at {now}"
            );
        }
    };
    let mut now = Time::ZERO;
    while now < Time::ZERO + Duration::from_secs(120) {
        let mut queue = Vec::new();
        for (k, a) in agents.iter_mut().enumerate() {
            a.tick(now, None);
            drain(a, k, now, &mut queue);
        }
        while let Some((from, o)) = queue.pop() {
            if let AgentOutput::Send { to, envelope, .. } = o {
                for t in targets(&to, from) {
                    agents[t].message(now, envelope.clone());
                    drain(&mut agents[t], t, now, &mut queue);
                }
            }
        }
        if agents.iter().all(|a| a.kernel().is_finished()) {
            break;
        }
        now += Duration::from_millis(100);
    }
    assert!(agents.iter().all(|a| a.kernel().is_finished()));
    assert!(
        kept > 0 && given_back > n,
        "kept {kept}, given back {given_back}"
    );
}
