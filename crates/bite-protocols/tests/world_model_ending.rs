//! The world model and a termination the kernel waits on (`term.wait-all`):
//! what the kernel ended on reaches the teammates even when the world model
//! was not due to decide at that tick.

use bite_core::graph::load_str;
use bite_core::time::Time;
use bite_core::wm::{Outgoing, Policy, Reason, Sharing, WorldModel};
use bite_core::{Kernel, Mission, RobotId, Value};
use std::sync::Arc;

/// Two robots push together until the box is half way; the team ends the
/// push when both have seen it (`term.wait-all`).
const PUSH: &str = r#"
graph: wm-ending
team: { robots: 2 }
start: push
defaults: { sync: sync.by-rule, allocate: alloc.by-id, terminate: term.wait-all }
behaviors:
  push: { team: true, skill: push, until: halfway }
"#;

/// Robot 0's kernel and its world model, deciding `hz` times a second.
fn pusher(hz: f64) -> (Kernel, WorldModel) {
    let g = load_str(&Arc::from("wm-ending.yaml"), PUSH).expect("the test graph loads");
    let n = g.symbols().len();
    let mission = Mission::new(g, &bite_protocols::registry()).expect("binds");
    let mut kernel = Kernel::new(Arc::new(mission), RobotId(0), 1);
    kernel.tick(Time::ZERO, &[]);
    let sharing = Sharing {
        policy: Policy::Focused,
        hz,
        budget: None,
    };
    let wm = WorldModel::new(RobotId(0), n, sharing, Arc::from(vec![false; n]));
    (kernel, wm)
}

/// One control tick as a robot's mind runs it (`bite_agent::Agent`): the
/// percept `halfway` through the world model, what it shares when due,
/// the kernel's tick, then what the kernel's ending makes it report.
fn tick(k: &mut Kernel, wm: &mut WorldModel, t: f64, halfway: Option<bool>) -> Vec<Outgoing> {
    let now = Time::from_secs_f64(t);
    let id = k
        .mission()
        .graph()
        .symbols()
        .get("halfway")
        .expect("belief");
    let percepts: Vec<_> = halfway.map(|h| (id, Value::Bool(h))).into_iter().collect();
    let (mut own, mut told) = (Vec::new(), Vec::new());
    wm.perceive(now, &percepts, &mut own, &mut told);
    k.observe(now, &own);
    if wm.due(now) {
        wm.share(now, k);
    }
    k.tick(now, &[]);
    wm.share_ending(now, k);
    std::iter::from_fn(|| wm.poll(now)).collect()
}

/// A world model that decides less often than its kernel ticks (a robot
/// whose clock runs slow: the hidden box, clock-skew seed 3335) was not due
/// at the one tick a noisy sighting made the push's condition hold. The
/// kernel ended the push there and waited for its teammate, which never
/// saw it, and no report ever went out (the condition no longer held at
/// the next decision): the team waited for ever. What the condition read
/// is now reported at once, and only once.
#[test]
fn a_condition_the_kernel_ended_on_between_two_decisions_is_reported_at_once() {
    let (mut k, mut wm) = pusher(5.0);
    assert!(tick(&mut k, &mut wm, 0.1, Some(false)).is_empty());
    // Not due at 0.2 (it decided at 0.1, next at 0.3): the kernel ends the
    // push on `halfway` and waits; the report goes out at once.
    let out = tick(&mut k, &mut wm, 0.2, Some(true));
    assert!(k.ending().is_some(), "waiting for its teammate");
    assert_eq!(out.len(), 1, "{out:?}");
    assert_eq!(out[0].msg.reason, Reason::Obligatory);
    assert_eq!(out[0].to, vec![RobotId(1)]);
    let names = bite_core::wm::belief_names(k.mission().graph(), &out[0].msg);
    assert_eq!(names, vec!["halfway"]);
    // The sighting was noise: no longer true, nothing more to report.
    for j in 3..30 {
        let out = tick(&mut k, &mut wm, f64::from(j) * 0.1, Some(false));
        assert!(out.is_empty(), "{j}: {out:?}");
    }
    // Due at the tick it ends: reported before the kernel acts, once; then,
    // while it holds and the team waits, told again a second on (`RESEND`).
    let (mut k, mut wm) = pusher(10.0);
    assert!(tick(&mut k, &mut wm, 0.1, Some(false)).is_empty());
    assert_eq!(tick(&mut k, &mut wm, 0.2, Some(true)).len(), 1);
    assert!(k.ending().is_some());
    let again: usize = (3..=15)
        .map(|j| tick(&mut k, &mut wm, f64::from(j) * 0.1, None).len())
        .sum();
    assert_eq!(again, 1);
}
