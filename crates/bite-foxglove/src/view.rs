//! What a run looks like at its latest record: each robot's behavior stack,
//! where everything is, the trajectories so far. Built from run-log records
//! alone (a simulated run's, a robot process's, the simulator server's), so
//! a live run, a converted log and a replay show the same thing.
//!
//! Pure: no clock, no IO.

use serde_json::Value as J;
use std::collections::BTreeMap;

/// One frame of a robot's behavior stack.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The behavior.
    pub behavior: String,
    /// Its subteam (short name, as logged).
    pub team: String,
}

/// A robot's pose: position in metres, heading in radians.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Heading, radians (counter-clockwise from +x).
    pub heading: f64,
}

/// A point of a trajectory, with the leaf behavior the robot ran there.
#[derive(Clone, Debug, PartialEq)]
pub struct TrailPoint {
    /// When, s.
    pub t: f64,
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// The leaf behavior (`None`: idle).
    pub behavior: Option<String>,
}

/// One robot as the records show it.
#[derive(Clone, Debug, Default)]
pub struct RobotView {
    /// The behavior stack, root first.
    pub stack: Vec<Frame>,
    /// Where it is (physical worlds).
    pub pose: Option<Pose>,
    /// The leaf behavior its body reports (physical worlds).
    pub moving_as: Option<String>,
    /// The robot whose slot it keeps or whom it follows.
    pub link: Option<usize>,
    /// Its trajectory, one point every [`TRAIL_EVERY`] seconds.
    pub trail: Vec<TrailPoint>,
    /// Teammates it presumes lost.
    pub lost: Vec<String>,
    /// It completed the mission.
    pub completed: bool,
    /// Its mind crashed (and has not resumed).
    pub crashed: bool,
    /// Beliefs it has reported (a condition that held, a status), by name.
    pub beliefs: BTreeMap<String, J>,
    /// World-model informs it has sent (Algorithm 3).
    pub informs: u64,
    /// Its authentication counters (a robot process's status or last
    /// record: `{"accepted": n, "rejected": {...}}`).
    pub auth: Option<J>,
    /// Where its control algorithm is (a robot process's status).
    pub phase: Option<String>,
}

/// A protocol instance: one interaction at one point, as its
/// participants logged it.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// `behavior.kind` (`walk.sync`): the coordination point.
    pub point: String,
    /// The subteam deciding.
    pub team: String,
    /// Epoch and round of the instance.
    pub epoch: u64,
    /// Round of the instance.
    pub round: u64,
    /// The bound protocol.
    pub protocol: String,
    /// When the first participant started it, s.
    pub started: f64,
    /// Participants that started it.
    pub waiting: Vec<String>,
    /// Participants that decided, with their outcomes.
    pub decided: Vec<(String, J)>,
    /// Messages sent and received, bytes sent, over the decided
    /// participants.
    pub sent: u64,
    /// Messages received.
    pub received: u64,
    /// Bytes sent.
    pub bytes: u64,
    /// Some participant decided on its deadline.
    pub timed_out: bool,
}

/// One joint decision: an instance's first `interaction_decided`, with
/// whether every participant that decided agreed.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    /// When, s.
    pub t: f64,
    /// The instance's key in [`View::instances`].
    pub key: String,
}

/// Seconds between two kept trajectory points.
pub const TRAIL_EVERY: f64 = 0.5;

/// What a record changed, for whoever draws it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Changed {
    /// A robot's behavior stack (its index in [`View::robots`]).
    pub stack: Option<usize>,
    /// Poses moved.
    pub poses: bool,
    /// The world's layout arrived.
    pub layout: bool,
}

/// The run at its latest record.
#[derive(Clone, Debug, Default)]
pub struct View {
    /// Simulated time of the latest record, s.
    pub t: f64,
    /// Robot names, in the order first seen (the roster order once poses
    /// or the layout have named them).
    pub names: Vec<String>,
    /// Robots, by the index of [`View::names`].
    pub robots: Vec<RobotView>,
    /// The `world` record (arena, obstacles, objects, zones, behaviors,
    /// palette), if the run has a physical world.
    pub layout: Option<J>,
    /// Each named object's position.
    pub objects: BTreeMap<String, [f64; 2]>,
    /// The `run_started` record.
    pub started: Option<J>,
    /// The summary of `run_finished`.
    pub summary: Option<J>,
    /// Protocol instances by key (`point/team/epoch/round`).
    pub instances: BTreeMap<String, Instance>,
    /// Joint decisions in the order they were first logged.
    pub decisions: Vec<Decision>,
    /// Records taken into account.
    pub records: u64,
}

/// The key of an `interaction_*` record's instance.
fn instance_key(rec: &J) -> Option<(String, String, u64, u64)> {
    let i = &rec["instance"];
    let point = format!("{}.{}", i["behavior"].as_str()?, i["kind"].as_str()?);
    Some((
        point,
        i["team"].as_str().unwrap_or("").to_string(),
        i["epoch"].as_u64().unwrap_or(0),
        i["round"].as_u64().unwrap_or(0),
    ))
}

impl View {
    /// An empty view.
    pub fn new() -> Self {
        View::default()
    }

    /// The index of robot `name`, adding it if new.
    pub fn robot(&mut self, name: &str) -> usize {
        match self.names.iter().position(|n| n == name) {
            Some(i) => i,
            None => {
                self.names.push(name.to_string());
                self.robots.push(RobotView::default());
                self.names.len() - 1
            }
        }
    }

    /// Take one record into account; says what changed.
    pub fn apply(&mut self, rec: &J) -> Changed {
        let mut changed = Changed::default();
        self.records = self.records.saturating_add(1);
        if let Some(t) = rec["t"].as_f64() {
            self.t = self.t.max(t);
        }
        let event = rec["event"].as_str().unwrap_or("");
        match event {
            "run_started" | "server_started" => {
                if self.started.is_none() || event == "run_started" {
                    self.started = Some(rec.clone());
                }
                // The server names the roster in order.
                for n in rec["robots"].as_array().into_iter().flatten() {
                    if let Some(n) = n.as_str() {
                        self.robot(n);
                    }
                }
            }
            "world" => {
                // The roster, in order: what `poses` and `links` index.
                for n in rec["robots"].as_array().into_iter().flatten() {
                    if let Some(n) = n.as_str() {
                        self.robot(n);
                    }
                }
                self.layout = Some(rec.clone());
                changed.layout = true;
            }
            "run_finished" if rec["summary"].is_object() => {
                self.summary = Some(rec["summary"].clone());
            }
            "poses" => {
                self.poses(rec);
                changed.poses = true;
            }
            _ => {}
        }
        let Some(name) = rec["robot"].as_str() else {
            return changed;
        };
        let i = self.robot(name);
        if event == "interaction_started" || event == "interaction_decided" {
            self.interaction(name, event, rec);
        }
        let r = &mut self.robots[i];
        match event {
            "selected" => {
                let depth = rec["depth"].as_u64().unwrap_or(r.stack.len() as u64) as usize;
                r.stack.truncate(depth);
                r.stack.push(Frame {
                    behavior: rec["behavior"].as_str().unwrap_or("?").to_string(),
                    team: rec["team"].as_str().unwrap_or("").to_string(),
                });
                changed.stack = Some(i);
            }
            "terminated" => {
                let b = rec["behavior"].as_str().unwrap_or("");
                if let Some(at) = r.stack.iter().rposition(|f| f.behavior == b) {
                    r.stack.truncate(at);
                    changed.stack = Some(i);
                }
            }
            "mission_completed" => {
                r.completed = true;
                r.stack.clear();
                changed.stack = Some(i);
            }
            "member_lost" => {
                if let Some(m) = rec["member"].as_str()
                    && !r.lost.iter().any(|x| x == m)
                {
                    r.lost.push(m.to_string());
                }
            }
            "member_back" => {
                if let Some(m) = rec["member"].as_str() {
                    r.lost.retain(|x| x != m);
                }
            }
            // A restarted robot starts with an empty mind (a crashed one
            // that resumes keeps its own).
            "restarted" => {
                r.stack.clear();
                r.crashed = false;
                changed.stack = Some(i);
            }
            "crashed" => r.crashed = true,
            "resumed" => r.crashed = false,
            "condition_held" => {
                for b in rec["beliefs"].as_array().into_iter().flatten() {
                    if let Some(n) = b[0].as_str() {
                        r.beliefs.insert(n.to_string(), b[1].clone());
                    }
                }
            }
            "inform" => r.informs = r.informs.saturating_add(1),
            "run_finished" if rec["auth"].is_object() => r.auth = Some(rec["auth"].clone()),
            // A robot process's status (`bite/T/status/<robot>`, given the
            // event `status`): the whole of its state at once, for a
            // monitor that joins a running team.
            "status" => {
                if let Some(stack) = rec["stack"].as_array() {
                    r.stack = stack
                        .iter()
                        .map(|f| Frame {
                            behavior: f["behavior"].as_str().unwrap_or("?").to_string(),
                            team: f["team"].as_str().unwrap_or("").to_string(),
                        })
                        .collect();
                    changed.stack = Some(i);
                }
                if let Some(b) = rec["beliefs"].as_object() {
                    r.beliefs = b.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
                }
                if let Some(l) = rec["lost"].as_array() {
                    r.lost = l
                        .iter()
                        .filter_map(|x| x.as_str().map(String::from))
                        .collect();
                }
                if rec["auth"].is_object() {
                    r.auth = Some(rec["auth"].clone());
                }
                r.phase = rec["phase"].as_str().map(String::from);
                r.completed = rec["state"].as_str() == Some("completed");
            }
            _ => {}
        }
        changed
    }

    fn interaction(&mut self, robot: &str, event: &str, rec: &J) {
        let Some((point, team, epoch, round)) = instance_key(rec) else {
            return;
        };
        let key = format!("{point}/{team}/{epoch}/{round}");
        let t = rec["t"].as_f64().unwrap_or(self.t);
        let inst = self
            .instances
            .entry(key.clone())
            .or_insert_with(|| Instance {
                point,
                team,
                epoch,
                round,
                protocol: rec["protocol"].as_str().unwrap_or("").to_string(),
                started: t,
                waiting: Vec::new(),
                decided: Vec::new(),
                sent: 0,
                received: 0,
                bytes: 0,
                timed_out: false,
            });
        if event == "interaction_started" {
            if !inst.waiting.iter().any(|r| r == robot) {
                inst.waiting.push(robot.to_string());
            }
            return;
        }
        inst.waiting.retain(|r| r != robot);
        if inst.decided.is_empty() {
            self.decisions.push(Decision { t, key });
        }
        inst.decided
            .push((robot.to_string(), rec["outcome"].clone()));
        // Counts from a file or the network: saturating, never a panic.
        let count = |k: &str| rec[k].as_u64().unwrap_or(0);
        inst.sent = inst.sent.saturating_add(count("sent"));
        inst.received = inst.received.saturating_add(count("received"));
        inst.bytes = inst.bytes.saturating_add(count("bytes"));
        inst.timed_out |= rec["timed_out"].as_bool().unwrap_or(false);
    }

    /// Instances some participant has started and not yet decided.
    pub fn in_flight(&self) -> impl Iterator<Item = (&String, &Instance)> {
        self.instances.iter().filter(|(_, i)| !i.waiting.is_empty())
    }

    fn poses(&mut self, rec: &J) {
        let t = rec["t"].as_f64().unwrap_or(self.t);
        // The roster, in order: the layout names it (and the server's
        // start record).
        let roster = [self.layout.as_ref(), self.started.as_ref()]
            .into_iter()
            .flatten()
            .find_map(|r| r["robots"].as_array());
        let names: Vec<String> = roster
            .into_iter()
            .flatten()
            .filter_map(|n| n.as_str().map(String::from))
            .collect();
        let behaviors = rec["behaviors"].as_array();
        let links = rec["links"].as_array();
        for (k, p) in rec["robots"].as_array().into_iter().flatten().enumerate() {
            let (Some(x), Some(y), Some(deg)) = (p[0].as_f64(), p[1].as_f64(), p[2].as_f64())
            else {
                continue;
            };
            // Unnamed: the default roster's names.
            let name = names.get(k).cloned().unwrap_or_else(|| format!("r{k}"));
            let i = self.robot(&name);
            let r = &mut self.robots[i];
            r.pose = Some(Pose {
                x,
                y,
                heading: deg.to_radians(),
            });
            r.moving_as = behaviors
                .and_then(|b| b.get(k))
                .and_then(|b| b.as_str())
                .map(String::from);
            // Links name roster indices: the robot of that name here.
            let link = links
                .and_then(|l| l.get(k))
                .and_then(|l| l.as_u64())
                .map(|l| {
                    names
                        .get(l as usize)
                        .cloned()
                        .unwrap_or_else(|| format!("r{l}"))
                });
            let link = link.map(|n| self.robot(&n));
            let r = &mut self.robots[i];
            r.link = link;
            if r.trail.last().is_none_or(|p| t - p.t >= TRAIL_EVERY - 1e-9) {
                r.trail.push(TrailPoint {
                    t,
                    x,
                    y,
                    behavior: r.moving_as.clone(),
                });
            }
        }
        if let Some(objects) = rec["objects"].as_object() {
            for (name, p) in objects {
                if let (Some(x), Some(y)) = (p[0].as_f64(), p[1].as_f64()) {
                    self.objects.insert(name.clone(), [x, y]);
                }
            }
        }
    }

    /// The colour the pictures give behavior `name` (`#rrggbb`), from the
    /// layout's palette; grey for idle or unknown.
    pub fn behavior_colour(&self, name: Option<&str>) -> String {
        const IDLE: &str = "#bbbbbb";
        let Some(layout) = &self.layout else {
            return IDLE.into();
        };
        let (Some(name), Some(bs), Some(palette)) = (
            name,
            layout["behaviors"].as_array(),
            layout["palette"].as_array(),
        ) else {
            return IDLE.into();
        };
        match bs.iter().position(|b| b.as_str() == Some(name)) {
            Some(i) if !palette.is_empty() => palette[i % palette.len()]
                .as_str()
                .unwrap_or(IDLE)
                .to_string(),
            _ => IDLE.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn stacks_follow_selections_and_terminations() {
        let mut v = View::new();
        v.apply(&json!({"t":0.0,"robot":"r0","event":"selected","behavior":"formation","team":"root","depth":0}));
        v.apply(&json!({"t":0.0,"robot":"r0","event":"selected","behavior":"triangle","team":"root","depth":1}));
        v.apply(&json!({"t":1.0,"robot":"r0","event":"selected","behavior":"walk","team":"t1","depth":2}));
        let names: Vec<&str> = v.robots[0]
            .stack
            .iter()
            .map(|f| f.behavior.as_str())
            .collect();
        assert_eq!(names, ["formation", "triangle", "walk"]);
        let c = v.apply(
            &json!({"t":2.0,"robot":"r0","event":"terminated","behavior":"triangle","team":"root"}),
        );
        assert_eq!(c.stack, Some(0));
        assert_eq!(v.robots[0].stack.len(), 1);
        // A selection at a shallower depth replaces what was above it.
        v.apply(&json!({"t":3.0,"robot":"r0","event":"selected","behavior":"line","team":"root","depth":1}));
        assert_eq!(v.robots[0].stack[1].behavior, "line");
        assert_eq!(v.t, 3.0);
    }

    #[test]
    fn poses_move_robots_and_keep_a_sparse_trail() {
        let mut v = View::new();
        v.apply(&json!({"t":0.0,"event":"run_started","robots":2}));
        v.apply(
            &json!({"t":0.0,"event":"world","behaviors":["a","b"],"palette":["#111111","#222222"]}),
        );
        for k in 0..10 {
            let t = k as f64 * 0.1;
            v.apply(
                &json!({"t":t,"event":"poses","robots":[[t,0.0,90.0],[1.0,1.0,0.0]],
                            "objects":{"box":[2.0,2.0]},"behaviors":["b",null],"links":[null,0]}),
            );
        }
        let r0 = &v.robots[0];
        assert!((r0.pose.unwrap().heading - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        assert_eq!(r0.trail.len(), 2, "one point every half second");
        assert_eq!(v.robots[1].link, Some(0));
        assert_eq!(v.behavior_colour(Some("b")), "#222222");
        assert_eq!(v.behavior_colour(None), "#bbbbbb");
        assert_eq!(v.objects["box"], [2.0, 2.0]);
    }

    #[test]
    fn instances_gather_their_participants_and_decisions_in_order() {
        let mut v = View::new();
        let inst = json!({"team":"root","behavior":"walk","kind":"sync","epoch":1,"round":0});
        v.apply(&json!({"t":1.0,"robot":"r0","event":"interaction_started","instance":inst,"protocol":"sync.vote"}));
        v.apply(&json!({"t":1.0,"robot":"r1","event":"interaction_started","instance":inst,"protocol":"sync.vote"}));
        assert_eq!(v.in_flight().count(), 1);
        v.apply(&json!({"t":1.2,"robot":"r0","event":"interaction_decided","instance":inst,"protocol":"sync.vote",
                        "outcome":{"kind":"sync","behavior":"walk"},"sent":2,"received":1,"bytes":40,"timed_out":false}));
        v.apply(&json!({"t":1.3,"robot":"r1","event":"interaction_decided","instance":inst,"protocol":"sync.vote",
                        "outcome":{"kind":"sync","behavior":"walk"},"sent":2,"received":1,"bytes":40,"timed_out":true}));
        assert_eq!(v.in_flight().count(), 0);
        assert_eq!(v.decisions.len(), 1, "one decision per instance");
        let i = &v.instances[&v.decisions[0].key];
        assert_eq!(i.point, "walk.sync");
        assert_eq!((i.sent, i.received, i.bytes, i.timed_out), (4, 2, 80, true));
        assert_eq!(i.decided.len(), 2);
        assert_eq!(v.decisions[0].t, 1.2);
    }

    #[test]
    fn a_status_gives_the_whole_state_of_a_robot_process() {
        let mut v = View::new();
        let c = v.apply(
            &json!({"t":3.0,"robot":"r2","event":"status","state":"running","phase":"running",
            "stack":[{"behavior":"formation","team":"root"},{"behavior":"walk","team":"t1"}],
            "beliefs":{"peers_located":true},"lost":["r0"],"auth":{"accepted":5,"rejected":{}}}),
        );
        assert_eq!(c.stack, Some(0));
        let r = &v.robots[0];
        assert_eq!(r.stack.len(), 2);
        assert_eq!(r.beliefs["peers_located"], json!(true));
        assert_eq!(r.lost, ["r0"]);
        assert_eq!(r.phase.as_deref(), Some("running"));
        assert_eq!(r.auth.as_ref().unwrap()["accepted"], 5);
    }
}
