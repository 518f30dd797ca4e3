//! The simulator as a server (`bite sim serve`), like Player/Stage: it owns
//! the physical world, steps it on the team clock, publishes every robot's
//! sensor readings on `bite/<team>/sim/sensors/<robot>` at the scenario's
//! control rate, and applies the velocity commands robots publish on
//! `bite/<team>/sim/cmd/<robot>`. A real robot's body replaces it by
//! publishing the same readings and taking the same commands
//! (`docs/zenoh-interface.md`).
//!
//! A robot whose commands stop for `deadman` is stopped where it is (a
//! killed robot process leaves its body standing, as a crashed robot does
//! in the simulator).

use crate::Keys;
use crate::net::{Clock, NetOptions, unix_micros};
use bite_agent::scenario::Scenario;
use bite_agent::schema::Command;
use bite_core::graph::BehaviorGraph;
use bite_core::ids::RobotId;
use bite_core::time::Time;
use bite_sim::physics::World;
use serde_json::json;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{RecvTimeoutError, TrySendError};
use std::time::Duration;
use zenoh::Wait;

/// Queue tag of a ROS 2 `cmd_vel` sample (a robot name cannot start so).
const ROS_PREFIX: &str = "\u{0}ros2:";

/// How the server runs.
pub struct ServerOptions {
    /// The team (key prefix).
    pub team: String,
    /// How to join the Zenoh network.
    pub net: NetOptions,
    /// Team seconds per wall second.
    pub speed: f64,
    /// The team clock's origin, microseconds since the Unix epoch (default:
    /// when the server starts).
    pub start_at_us: Option<u64>,
    /// Stop after this much team time (default: run until stopped).
    pub time_limit: Option<Duration>,
    /// A robot without a command for this long (team time) is stopped.
    pub deadman: Duration,
    /// Where to write the world's log (poses once a second, JSON lines).
    pub log: Option<PathBuf>,
    /// Also be the bodies in ROS 2 terms (rmw_zenoh): each robot's
    /// odometry and range rays on `/<robot>/odom` and `/<robot>/scan`,
    /// driven by `/<robot>/cmd_vel` (docs/ros2.md).
    pub ros2: Option<crate::ros2::Ros2Options>,
}

/// What the server saw.
#[derive(Debug)]
pub struct ServeReport {
    /// Team time when it stopped.
    pub end: Time,
    /// Commands applied, per robot.
    pub commands: Vec<u64>,
    /// Commands dropped as malformed or from unknown robots.
    pub rejected: u64,
    /// The world at the end (for pictures).
    pub world: World,
}

/// Why the server could not run.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// Bad options or scenario.
    #[error("{0}")]
    Options(String),
    /// Zenoh.
    #[error(transparent)]
    Net(#[from] crate::net::ConfigError),
    /// Zenoh refused a declaration.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// The log.
    #[error("log {0}: {1}")]
    Log(PathBuf, std::io::Error),
}

/// Serve the physical world of `scenario` for the robots of `graph`'s
/// roster until `stop` is set or the time limit passes.
pub fn serve(
    graph: &BehaviorGraph,
    scenario: &Scenario,
    seed: u64,
    opts: &ServerOptions,
    stop: Arc<AtomicBool>,
) -> Result<ServeReport, ServeError> {
    let Some(spec) = &scenario.physics else {
        return Err(ServeError::Options(format!(
            "scenario `{}` is a timed world: the simulator server needs `world: physics`",
            scenario.name
        )));
    };
    crate::check_team(&opts.team, &[], opts.speed).map_err(ServeError::Options)?;
    let n = graph.roster().len();
    let names: Vec<String> = (0..n as u32)
        .map(|r| graph.roster().name(RobotId(r)))
        .collect();
    let index: BTreeMap<String, usize> = names
        .iter()
        .enumerate()
        .map(|(i, s)| (s.clone(), i))
        .collect();
    let mut world = World::new(spec.clone(), &names, graph.symbols(), &scenario.file, seed)
        .map_err(|d| {
            ServeError::Options(
                d.0.iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join("\n"),
            )
        })?;
    let keys = Keys::new(&opts.team);
    let session = opts.net.open()?;
    let z = |e: zenoh::Error| ServeError::Zenoh(e.to_string());
    let (tx, rx) = std::sync::mpsc::sync_channel::<(String, Vec<u8>)>(4096);
    let overflow = Arc::new(AtomicU64::new(0));
    let _cmds = {
        let tx = tx.clone();
        let overflow = overflow.clone();
        session
            .declare_subscriber(keys.all("sim/cmd"))
            .callback(move |s| {
                let from = Keys::robot_of(s.key_expr().as_str()).to_string();
                if let Err(TrySendError::Full(_)) =
                    tx.try_send((from, s.payload().to_bytes().into_owned()))
                {
                    overflow.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .map_err(z)?
    };
    // The ROS 2 side: one node per robot body, publishing its odometry and
    // scans, driven by its cmd_vel (samples without rmw_zenoh's attachment
    // are dropped and counted, as a ROS subscriber drops them).
    let ros_rejected = Arc::new(AtomicU64::new(0));
    let mut ros = Vec::new();
    let _ros_cmds = match opts.ros2 {
        None => None,
        Some(r) => {
            use crate::ros2;
            for name in &names {
                let ns = format!("/{name}");
                let mut node =
                    ros2::RosNode::declare(&session, r.domain, &ns, &format!("{name}_body"))
                        .map_err(z)?;
                let odom = node
                    .publisher(&session, &ros2::topic(&ns, "odom"), &ros2::ODOMETRY)
                    .map_err(z)?;
                let scan = node
                    .publisher(&session, &ros2::topic(&ns, "scan"), &ros2::LASER_SCAN)
                    .map_err(z)?;
                node.subscription(&session, &ros2::topic(&ns, "cmd_vel"), &ros2::TWIST)
                    .map_err(z)?;
                ros.push((node, odom, scan));
            }
            let tx = tx.clone();
            let overflow = overflow.clone();
            let rejected = ros_rejected.clone();
            let all = format!(
                "{}/*/cmd_vel/{}/{}",
                r.domain,
                ros2::TWIST.mangled,
                ros2::TWIST.hash
            );
            Some(
                session
                    .declare_subscriber(all)
                    .callback(move |s| {
                        let ok = s
                            .attachment()
                            .is_some_and(|a| ros2::parse_attachment(&a.to_bytes()).is_ok());
                        if !ok {
                            rejected.fetch_add(1, Ordering::Relaxed);
                            return;
                        }
                        // `<domain>/<robot>/cmd_vel/...`
                        let robot = s.key_expr().as_str().split('/').nth(1).unwrap_or("");
                        let from = format!("{ROS_PREFIX}{robot}");
                        if let Err(TrySendError::Full(_)) =
                            tx.try_send((from, s.payload().to_bytes().into_owned()))
                        {
                            overflow.fetch_add(1, Ordering::Relaxed);
                        }
                    })
                    .wait()
                    .map_err(z)?,
            )
        }
    };
    drop(tx);
    let mut log = (opts.log.as_deref().map(crate::create_log))
        .transpose()
        .map_err(|e| ServeError::Log(opts.log.clone().unwrap_or_default(), e))?;
    let clock = Clock {
        origin_us: opts.start_at_us.unwrap_or_else(unix_micros),
        speed: opts.speed,
    };
    let period = Duration::from_secs_f64(1.0 / scenario.control_hz);
    let deadman = opts.deadman;
    let mut last_cmd: Vec<Option<Time>> = vec![None; n];
    let mut commands = vec![0u64; n];
    // ROS 2 `cmd_vel` samples applied, and when the last came: a body
    // follows them while they keep coming, and its commands again after.
    let mut twists = vec![0u64; n];
    let mut last_twist: Vec<Option<Time>> = vec![None; n];
    let mut rejected = 0u64;
    let mut next = Time::ZERO;
    let mut next_world = Time::ZERO;
    let write = |log: &mut Option<std::io::BufWriter<std::fs::File>>, rec: serde_json::Value| {
        let line = rec.to_string();
        let _ = session.put(keys.world(), line.clone()).wait();
        // Flushed at once (a line a second): whoever follows the log
        // (`bite launch --foxglove`) sees the world as it goes.
        if let Some(w) = log.as_mut() {
            writeln!(w, "{line}").and_then(|_| w.flush())
        } else {
            Ok(())
        }
    };
    write(
        &mut log,
        json!({"t": 0.0, "event": "server_started", "scenario": scenario.name, "graph": graph.name(),
               "robots": names, "seed": seed, "speed": opts.speed}),
    )
    .map_err(|e| ServeError::Log(opts.log.clone().unwrap_or_default(), e))?;
    let behaviors: Vec<String> = (0..graph.len())
        .map(|b| {
            graph
                .name_of(bite_core::ids::BehaviorId(b as u32))
                .to_string()
        })
        .collect();
    let layout = world.layout_record(&names, &behaviors);
    // A viewer that joins later asks for the layout (`get` on the world's
    // key); the poses follow once a second.
    let _layout_queryable = {
        let line = layout.to_string();
        let key = keys.world();
        session
            .declare_queryable(keys.world())
            .callback(move |q| {
                let _ = q.reply(key.clone(), line.clone()).wait();
            })
            .wait()
            .map_err(z)?
    };
    write(&mut log, layout)
        .map_err(|e| ServeError::Log(opts.log.clone().unwrap_or_default(), e))?;
    let end = loop {
        let now = clock.now();
        if stop.load(Ordering::Relaxed) {
            break now;
        }
        if let Some(l) = opts.time_limit
            && now >= Time::ZERO + l
        {
            break now;
        }
        if now >= next {
            next = now + period;
            let stopped: Vec<bool> = last_cmd
                .iter()
                .map(|c| c.is_none_or(|c| now.saturating_since(c) > deadman))
                .collect();
            for (i, at) in last_twist.iter_mut().enumerate() {
                if at.is_some_and(|t| now.saturating_since(t) > deadman) {
                    world.clear_twist(i);
                    *at = None;
                }
            }
            world.advance(now, &stopped);
            world.record();
            for (i, name) in names.iter().enumerate() {
                let s = world.observe(i);
                if let Some((_, odom, scan)) = ros.get_mut(i) {
                    use crate::ros2;
                    let t = now.as_secs_f64();
                    let (forward, turn) = world.body_velocity(i);
                    let o = ros2::odometry(
                        t,
                        (&format!("{name}/odom"), &format!("{name}/base_link")),
                        [s.pose.pos.x, s.pose.pos.y, s.pose.heading],
                        [forward, turn],
                    );
                    odom.put(&session, &o);
                    let sensors = spec.sensors;
                    let l = ros2::scan_of(
                        t,
                        &format!("{name}/base_scan"),
                        sensors.rays as usize,
                        sensors.ray_range,
                        &s.rays,
                    );
                    scan.put(&session, &l);
                }
                if let Ok(body) = serde_json::to_vec(&s) {
                    let _ = session.put(keys.sensors(name), body).wait();
                }
            }
            if now >= next_world {
                next_world = now + Duration::from_secs(1);
                let name = |b: bite_core::ids::BehaviorId| graph.name_of(b).to_string();
                let mut rec = world.poses_record(now.as_secs_f64(), &name);
                rec["stopped"] = json!(stopped);
                write(&mut log, rec)
                    .map_err(|e| ServeError::Log(opts.log.clone().unwrap_or_default(), e))?;
            }
        }
        let wait_us = (next.as_secs_f64() / clock.speed * 1e6) as u64 + clock.origin_us;
        let wait = Duration::from_micros(wait_us.saturating_sub(unix_micros()))
            .min(Duration::from_millis(100));
        match rx.recv_timeout(wait) {
            Ok(first) => {
                let mut batch = vec![first];
                while let Ok(m) = rx.try_recv() {
                    batch.push(m);
                }
                let now = clock.now();
                for (from, bytes) in batch {
                    if let Some(robot) = from.strip_prefix(ROS_PREFIX) {
                        let twist =
                            crate::ros2::decode::<crate::ros2::Twist>(&crate::ros2::TWIST, &bytes);
                        match (index.get(robot), twist) {
                            (Some(&i), Ok(t)) => {
                                world.actuate_twist(i, t.linear.x, t.linear.y, t.angular.z);
                                last_cmd[i] = Some(now);
                                last_twist[i] = Some(now);
                                twists[i] += 1;
                            }
                            _ => rejected += 1,
                        }
                        continue;
                    }
                    let Some(&i) = index.get(&from) else {
                        rejected += 1;
                        continue;
                    };
                    match serde_json::from_slice::<Command>(&bytes) {
                        Ok(cmd) => {
                            world.actuate(i, cmd);
                            // Driven by cmd_vel: the command only labels
                            // the trail.
                            if last_twist[i].is_none() {
                                last_cmd[i] = Some(now);
                                commands[i] += 1;
                            }
                        }
                        Err(_) => rejected += 1,
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break clock.now(),
        }
    };
    let rec = json!({"t": end.as_secs_f64(), "event": "server_stopped", "commands": commands,
                     "twists": twists, "rejected": rejected, "overflow": overflow.load(Ordering::Relaxed),
                     "ros2_rejected": ros_rejected.load(Ordering::Relaxed)});
    write(&mut log, rec).map_err(|e| ServeError::Log(opts.log.clone().unwrap_or_default(), e))?;
    if let Some(mut w) = log {
        w.flush()
            .map_err(|e| ServeError::Log(opts.log.clone().unwrap_or_default(), e))?;
    }
    let _ = session.close().wait();
    Ok(ServeReport {
        end,
        commands,
        rejected,
        world,
    })
}
