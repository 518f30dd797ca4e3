//! `bite launch`: robots gone silent while their teammates finished.
//!
//! A robot process that is frozen (`kill -STOP`) or hung does not exit:
//! its teammates presume it lost, complete the mission without it and
//! leave, and the launcher would wait for it until the wall limit. From
//! the robots' run logs the launcher follows, [`Watch`] sees when every
//! robot still running is presumed lost by a teammate that completed, and
//! none of them has written a record for [`GRACE`]: those are stopped and
//! reported unresponsive.

use serde_json::Value as J;
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

/// How long (wall time) robots presumed lost by teammates that completed
/// may stay silent, once they are the only ones still running, before
/// `bite launch` stops them (docs/zenoh-interface.md).
pub const GRACE: Duration = Duration::from_secs(5);

/// What the run logs say so far: who completed, whom the others presume
/// lost, when each robot last wrote a record.
#[derive(Debug, Default)]
pub struct Watch {
    completed: BTreeSet<String>,
    /// By robot: the teammates whose latest word on it is `member_lost`.
    lost_by: BTreeMap<String, BTreeSet<String>>,
    /// Wall µs at which a record of each robot was last seen.
    heard: BTreeMap<String, u64>,
    /// Wall µs since when the only robots still running are presumed lost.
    since: Option<u64>,
    /// By robot: the team time (`t`) of its latest record.
    last_t: BTreeMap<String, f64>,
    /// By robot: the team time of the latest `member_lost` on it.
    lost_t: BTreeMap<String, f64>,
}

impl Watch {
    /// A record of a robot's run log, seen at wall time `now_us`.
    pub fn see(&mut self, rec: &J, now_us: u64) {
        let Some(robot) = rec["robot"].as_str() else {
            return;
        };
        self.heard.insert(robot.to_string(), now_us);
        let t = rec["t"].as_f64();
        if let Some(t) = t {
            let last = self.last_t.entry(robot.to_string()).or_insert(t);
            *last = last.max(t);
        }
        let member = rec["member"].as_str();
        match (rec["event"].as_str(), member) {
            (Some("mission_completed"), _) => {
                self.completed.insert(robot.to_string());
            }
            (Some("member_lost"), Some(m)) => {
                self.lost_by
                    .entry(m.to_string())
                    .or_default()
                    .insert(robot.to_string());
                if let Some(t) = t {
                    let at = self.lost_t.entry(m.to_string()).or_insert(t);
                    *at = at.max(t);
                }
            }
            (Some("member_back"), Some(m)) => {
                if let Some(by) = self.lost_by.get_mut(m) {
                    by.remove(robot);
                }
            }
            _ => {}
        }
    }

    /// Presumed lost by a teammate that completed the mission (and has not
    /// heard it again since), and silent in its own log since: a robot
    /// that wrote a record (team time) after it was presumed lost is alive,
    /// only cut off or slow, and goes on alone (it was frozen, then
    /// resumed after its teammates left): it is never stopped.
    fn presumed_lost(&self, robot: &str) -> bool {
        let wrote_since = match (self.last_t.get(robot), self.lost_t.get(robot)) {
            (Some(last), Some(lost)) => last > lost,
            _ => false,
        };
        !wrote_since
            && (self.lost_by.get(robot))
                .is_some_and(|by| by.iter().any(|b| self.completed.contains(b)))
    }

    /// The processes to stop now, by their index in `running` (the robots
    /// of each process, `None` for one that has exited): when every robot
    /// still running has completed or is presumed lost, at least one is
    /// presumed lost and has not completed, and none of those has written
    /// a record for [`GRACE`], the processes running them.
    pub fn silent(&mut self, running: &[Option<&[String]>], now_us: u64) -> Vec<usize> {
        let alive = running.iter().flatten().flat_map(|g| g.iter());
        let settled = alive
            .clone()
            .all(|r| self.completed.contains(r) || self.presumed_lost(r));
        let silent: Vec<&String> = alive
            .filter(|r| !self.completed.contains(*r) && self.presumed_lost(r))
            .collect();
        if !settled || silent.is_empty() {
            self.since = None;
            return Vec::new();
        }
        let since = *self.since.get_or_insert(now_us);
        let last = silent.iter().filter_map(|r| self.heard.get(*r)).max();
        let quiet_from = last.map_or(since, |l| since.max(*l));
        if now_us.saturating_sub(quiet_from) < GRACE.as_micros() as u64 {
            return Vec::new();
        }
        (running.iter().enumerate())
            .filter(|(_, g)| g.is_some_and(|g| g.iter().any(|r| silent.contains(&r))))
            .map(|(i, _)| i)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    const S: u64 = 1_000_000;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_frozen_robot_is_stopped_after_the_grace_once_its_teammates_completed() {
        let (r0, r1, r2) = (names(&["r0"]), names(&["r1"]), names(&["r2"]));
        let mut w = Watch::default();
        w.see(&json!({"robot": "r1", "event": "selected"}), 10 * S);
        // r1 freezes at 10 s; r0 and r2 presume it lost, then complete.
        for r in ["r0", "r2"] {
            w.see(
                &json!({"robot": r, "event": "member_lost", "member": "r1"}),
                15 * S,
            );
        }
        let all = [Some(&r0[..]), Some(&r1[..]), Some(&r2[..])];
        assert!(w.silent(&all, 16 * S).is_empty(), "r0 and r2 still work");
        for r in ["r0", "r2"] {
            w.see(&json!({"robot": r, "event": "mission_completed"}), 30 * S);
        }
        assert!(w.silent(&all, 31 * S).is_empty(), "within the grace");
        let gone = [None, Some(&r1[..]), None];
        assert_eq!(w.silent(&gone, 31 * S + GRACE.as_micros() as u64), vec![1]);
    }

    /// Frozen past its teammates' patience, then resumed after they
    /// completed: it writes on (team time after the loss), and is left to
    /// finish alone.
    #[test]
    fn a_robot_that_wrote_after_it_was_presumed_lost_is_not_stopped() {
        let r1 = names(&["r1"]);
        let mut w = Watch::default();
        w.see(
            &json!({"robot": "r1", "t": 10.0, "event": "selected"}),
            10 * S,
        );
        w.see(
            &json!({"robot": "r0", "t": 15.0, "event": "member_lost", "member": "r1"}),
            15 * S,
        );
        w.see(
            &json!({"robot": "r0", "t": 30.0, "event": "mission_completed"}),
            30 * S,
        );
        w.see(
            &json!({"robot": "r1", "t": 31.0, "event": "member_lost", "member": "r0"}),
            31 * S,
        );
        let run = [None, Some(&r1[..])];
        assert!(
            w.silent(&run, 31 * S + 10 * GRACE.as_micros() as u64)
                .is_empty()
        );
    }

    #[test]
    fn a_robot_heard_again_or_still_writing_is_not_stopped() {
        let (r0, r1) = (names(&["r0"]), names(&["r1"]));
        let run = [None, Some(&r1[..])];
        let mut w = Watch::default();
        w.see(
            &json!({"robot": "r0", "event": "member_lost", "member": "r1"}),
            S,
        );
        w.see(
            &json!({"robot": "r0", "event": "member_back", "member": "r1"}),
            2 * S,
        );
        w.see(&json!({"robot": "r0", "event": "mission_completed"}), 3 * S);
        assert!(w.silent(&run, 60 * S).is_empty(), "heard again");
        w.see(
            &json!({"robot": "r0", "event": "member_lost", "member": "r1"}),
            4 * S,
        );
        assert!(w.silent(&run, 9 * S).is_empty());
        // r1 still writes its log: alive, cut off from r0; silent from
        // its last record on.
        w.see(&json!({"robot": "r1", "event": "selected"}), 10 * S);
        let grace = GRACE.as_micros() as u64;
        assert!(w.silent(&run, 9 * S + grace).is_empty());
        assert_eq!(w.silent(&run, 10 * S + grace), vec![1]);
        // A teammate that presumed it lost but has not completed holds it.
        let mut w = Watch::default();
        w.see(
            &json!({"robot": "r0", "event": "member_lost", "member": "r1"}),
            S,
        );
        assert!(w.silent(&[Some(&r0[..]), Some(&r1[..])], 60 * S).is_empty());
        assert!(w.silent(&run, 60 * S).is_empty(), "r0 never completed");
    }

    #[test]
    fn a_process_of_several_robots_is_stopped_when_its_silent_robot_is() {
        let both = names(&["r0", "r1"]);
        let mut w = Watch::default();
        w.see(
            &json!({"robot": "r2", "event": "member_lost", "member": "r1"}),
            S,
        );
        w.see(&json!({"robot": "r2", "event": "mission_completed"}), S);
        w.see(&json!({"robot": "r0", "event": "mission_completed"}), S);
        let run = [Some(&both[..]), None];
        assert!(w.silent(&run, 2 * S).is_empty());
        assert_eq!(w.silent(&run, 2 * S + GRACE.as_micros() as u64), vec![0]);
    }
}
