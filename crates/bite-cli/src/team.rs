//! Robots as separate processes over Zenoh: `bite robot`, `bite sim serve`,
//! `bite launch`, `bite submit`, `bite keygen`.

use anyhow::{Context, Result, bail};
use bite_core::graph::BehaviorGraph;
use bite_sim::Scenario;
use bite_zenoh::auth::TeamKey;
use bite_zenoh::net::{NetOptions, unix_micros};
use bite_zenoh::robot::{Prepared, RobotOptions};
use bite_zenoh::wire::MissionBody;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, ExitCode, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::{Reported, parse_dur, parse_robots, rtcl};

/// How a process joins the team's Zenoh network.
#[derive(clap::Args, Clone, Debug)]
pub struct NetArgs {
    /// The team: the `bite/<team>/` key prefix.
    #[arg(long, default_value = "bite")]
    pub team: String,
    /// Endpoint to listen on, e.g. `tcp/127.0.0.1:7447` (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
    /// Endpoint to connect to (repeatable).
    #[arg(long)]
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5: TLS, access control, routers);
    /// `--listen`, `--connect` and `--multicast` are laid over it.
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// Turn multicast scouting on (off by default; give `--multicast-interface lo` on one machine).
    #[arg(long)]
    pub multicast: bool,
    /// The network interface multicast scouting uses.
    #[arg(long)]
    pub multicast_interface: Option<String>,
    /// Zenoh mode: `peer` (default) or `client` (through a zenohd router).
    #[arg(long)]
    pub mode: Option<String>,
}

impl NetArgs {
    fn options(&self) -> NetOptions {
        NetOptions {
            config: self.zenoh_config.clone(),
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            multicast: self.multicast,
            multicast_interface: self.multicast_interface.clone(),
            mode: self.mode.clone(),
        }
    }
}

/// What mission to run and in which world (as `bite run` takes it).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct MissionArgs {
    /// The behavior graph (YAML) or mission (`.rtcl`). Default for `robot`:
    /// none, wait for one to be submitted; for `sim serve` and `launch`:
    /// the built-in formation example.
    pub graph: Option<PathBuf>,
    /// The command library for `.rtcl` missions.
    #[arg(long)]
    pub library: Option<PathBuf>,
    /// A configuration file binding protocols to points.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The scenario (default: next to the graph, physical world first).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Team size.
    #[arg(long, value_parser = parse_robots)]
    pub robots: Option<usize>,
    /// Seed (default: the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Use the timed-skill world when picking the default scenario.
    #[arg(long)]
    pub timed: bool,
    /// Run the built-in formation example (what `bite run` runs with no
    /// graph) rather than wait for a submitted mission. `launch` and
    /// `sim serve` run it when no graph is given; this makes a robot do so.
    #[arg(long, conflicts_with = "graph")]
    pub built_in: bool,
}

impl MissionArgs {
    /// The graph and scenario, as `bite run` loads them.
    fn load(&self) -> Result<(BehaviorGraph, Scenario)> {
        crate::load_team(
            self.graph.as_deref(),
            self.library.as_deref(),
            self.config.as_deref(),
            self.scenario.as_deref(),
            self.robots,
            self.timed,
        )
    }

    /// The input files these arguments name (flag, path), which no output
    /// may overwrite.
    fn inputs(&self) -> Vec<(&'static str, &Path)> {
        [
            ("graph", &self.graph),
            ("--library", &self.library),
            ("--config", &self.config),
            ("--scenario", &self.scenario),
        ]
        .into_iter()
        .filter_map(|(what, p)| p.as_deref().map(|p| (what, p)))
        .collect()
    }

    /// The world a robot started with these arguments runs submitted missions
    /// in when they carry none: its `--scenario`, or its graph's (as
    /// [`MissionArgs::load`] resolves it); none without either.
    fn own_scenario(&self) -> Result<Option<Scenario>> {
        if self.graph.is_some() || self.built_in {
            return Ok(Some(self.load()?.1));
        }
        match &self.scenario {
            Some(p) => Ok(Some(Scenario::load(p).map_err(crate::bad_input)?)),
            None => Ok(None),
        }
    }

    /// These arguments as JSON, with absolute paths (what a record of a
    /// robot's inputs says its mission was made from).
    fn origin(&self) -> serde_json::Value {
        let abs = |p: &Option<PathBuf>| {
            p.as_ref()
                .map(|p| std::path::absolute(p).unwrap_or_else(|_| p.clone()))
        };
        serde_json::json!({
            "graph": abs(&self.graph),
            "library": abs(&self.library),
            "config": abs(&self.config),
            "scenario": abs(&self.scenario),
            "robots": self.robots,
            "seed": self.seed,
            "timed": self.timed,
            "built_in": self.built_in,
        })
    }

    /// The arguments [`MissionArgs::origin`] wrote, in the record `file`;
    /// a team size out of `--robots`' bounds is an error naming the file.
    fn from_origin(v: &serde_json::Value, file: &Path) -> Result<MissionArgs> {
        let path = |k: &str| v[k].as_str().map(PathBuf::from);
        Ok(MissionArgs {
            graph: path("graph"),
            library: path("library"),
            config: path("config"),
            scenario: path("scenario"),
            robots: origin_robots(&v["robots"], file)?,
            seed: v["seed"].as_u64(),
            timed: v["timed"].as_bool().unwrap_or(false),
            built_in: v["built_in"].as_bool().unwrap_or(false),
        })
    }

    /// Arguments that give the same mission to a child process.
    /// Without a graph, the built-in example, said explicitly so that a
    /// robot runs it rather than waits for a submission.
    fn to_args(&self) -> Vec<String> {
        let mut a = Vec::new();
        match &self.graph {
            Some(g) => a.push(g.display().to_string()),
            None => a.push("--built-in".into()),
        }
        let mut opt = |k: &str, v: Option<String>| {
            if let Some(v) = v {
                a.push(k.to_string());
                a.push(v);
            }
        };
        opt(
            "--library",
            self.library.as_ref().map(|p| p.display().to_string()),
        );
        opt(
            "--config",
            self.config.as_ref().map(|p| p.display().to_string()),
        );
        opt(
            "--scenario",
            self.scenario.as_ref().map(|p| p.display().to_string()),
        );
        opt("--robots", self.robots.map(|n| n.to_string()));
        opt("--seed", self.seed.map(|n| n.to_string()));
        if self.timed {
            a.push("--timed".into());
        }
        a
    }
}

/// How a robot publishes its authenticated frames.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FramesArg {
    /// `put` on the session, frame by frame.
    Put,
    /// A publisher declared once (Zenoh may batch frames when the link is busy).
    #[default]
    Declared,
    /// A publisher declared once, express: each frame leaves at once.
    Express,
}

impl FramesArg {
    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        self.publish().name()
    }

    pub fn publish(self) -> bite_zenoh::robot::Publish {
        use bite_zenoh::robot::Publish;
        match self {
            FramesArg::Put => Publish::Put,
            FramesArg::Declared => Publish::Declared,
            FramesArg::Express => Publish::Express,
        }
    }
}

/// The threads Zenoh's runtime runs its network tasks on in each robot
/// process launched (the `ZENOH_RUNTIME` environment variable of Zenoh 1.x,
/// which `bite robot` reads too).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RuntimeArg {
    /// Zenoh's defaults: five runtimes, six worker threads (rx two).
    Zenoh,
    /// Every runtime handed over to one, with one worker thread.
    #[default]
    Shared1,
    /// Every runtime handed over to one, with two worker threads.
    Shared2,
}

impl RuntimeArg {
    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            RuntimeArg::Zenoh => "zenoh",
            RuntimeArg::Shared1 => "shared1",
            RuntimeArg::Shared2 => "shared2",
        }
    }

    /// The value of `ZENOH_RUNTIME` (RON), if any.
    pub fn env(self) -> Option<String> {
        let shared = |n: usize| {
            format!(
                "(app: (worker_threads: {n}), acc: (handover: app), tx: (handover: app), \
                 rx: (handover: app), net: (handover: app))"
            )
        };
        match self {
            RuntimeArg::Zenoh => None,
            RuntimeArg::Shared1 => Some(shared(1)),
            RuntimeArg::Shared2 => Some(shared(2)),
        }
    }
}

/// How a launched team's robots are laid out in processes and talk to
/// each other (docs/performance.md measures each).
#[derive(clap::Args, Clone, Debug)]
pub struct Tuning {
    /// Robots per process: N robots in each `bite robot` process (each
    /// robot its own thread, keys, status and log, the N sharing one
    /// Zenoh session). `--kill` kills a robot's process, so its N robots.
    #[arg(long, default_value_t = 1, value_parser = parse_per_process)]
    pub per_process: usize,
    /// How the robots publish their frames.
    #[arg(long, value_enum, default_value_t)]
    pub frames: FramesArg,
    /// Zenoh's runtime threads in each robot process (sets `ZENOH_RUNTIME`
    /// for them; `zenoh`: leave it as it is).
    #[arg(long, value_enum, default_value_t)]
    pub zenoh_runtime: RuntimeArg,
}

impl Default for Tuning {
    fn default() -> Self {
        Tuning {
            per_process: 1,
            frames: FramesArg::default(),
            zenoh_runtime: RuntimeArg::default(),
        }
    }
}

impl Tuning {
    /// A short label, e.g. `per-process 1, frames express, runtime shared1`.
    pub fn label(&self) -> String {
        format!(
            "per-process {}, frames {}, runtime {}",
            self.per_process,
            self.frames.name(),
            self.zenoh_runtime.name()
        )
    }
}

fn parse_per_process(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=1000).contains(&n) => Ok(n),
        _ => Err(format!(
            "`{s}`: robots per process is a number from 1 to 1000"
        )),
    }
}

#[derive(clap::Args)]
pub struct RobotArgs {
    /// This robot's name on the mission's roster (e.g. `r0`). Repeat it to
    /// run several robots in this one process, sharing one Zenoh session
    /// (each its own thread, keys, status and log: `--log` and `--record`
    /// then name each robot's file with `{name}`, e.g. `out/{name}.jsonl`).
    #[arg(long, required = true)]
    pub name: Vec<String>,
    /// How the robots publish their frames.
    #[arg(long, value_enum, default_value_t)]
    pub frames: FramesArg,
    /// Speak ROS 2 for the robots' bodies, on rmw_zenoh's wire conventions,
    /// in this ROS domain (default 0): `/<robot>/odom`
    /// (`nav_msgs/msg/Odometry`), `/<robot>/scan` (`sensor_msgs/msg/LaserScan`),
    /// `/<robot>/cmd_vel` (`geometry_msgs/msg/Twist`), `/<robot>/bite/status`
    /// (`std_msgs/msg/String`). See docs/ros2.md.
    #[arg(long, value_name = "DOMAIN", num_args = 0..=1, default_missing_value = "0")]
    pub ros2: Option<u32>,

    #[command(flatten)]
    pub mission: MissionArgs,
    #[command(flatten)]
    pub net: NetArgs,
    /// The team key file (hex, 32 bytes or more; `bite keygen` makes one).
    /// Also read from `BITE_TEAM_KEY`. A robot without a valid key does not start.
    #[arg(long)]
    pub key: Option<PathBuf>,
    /// Team seconds per wall second (1 for real robots; a simulator server
    /// and every robot of the team must agree).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// The team clock's origin, milliseconds since the Unix epoch (shared
    /// by the team; default: when every teammate has been heard).
    #[arg(long)]
    pub start_at: Option<u64>,
    /// Where to write the run log (JSON lines).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Exit once the mission is completed.
    #[arg(long)]
    pub exit_when_done: bool,
    /// Record every input of the robot's mind to this file (JSON lines),
    /// for `bite replay`.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Give up after this much team time (e.g. `300s`).
    #[arg(long, value_parser = parse_dur)]
    pub time_limit: Option<Duration>,
    /// How long to wait for every teammate before starting anyway (wall).
    #[arg(long, value_parser = parse_dur, default_value = "10s")]
    pub gather_timeout: Duration,
}

#[derive(clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    pub mission: MissionArgs,
    /// Speak ROS 2 for the robots' bodies, on rmw_zenoh's wire conventions,
    /// in this ROS domain (default 0): `/<robot>/odom`
    /// (`nav_msgs/msg/Odometry`), `/<robot>/scan` (`sensor_msgs/msg/LaserScan`),
    /// `/<robot>/cmd_vel` (`geometry_msgs/msg/Twist`), `/<robot>/bite/status`
    /// (`std_msgs/msg/String`). See docs/ros2.md.
    #[arg(long, value_name = "DOMAIN", num_args = 0..=1, default_missing_value = "0")]
    pub ros2: Option<u32>,

    #[command(flatten)]
    pub net: NetArgs,
    /// Team seconds per wall second.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// The team clock's origin, milliseconds since the Unix epoch.
    #[arg(long)]
    pub start_at: Option<u64>,
    /// Where to write the world's log (JSON lines).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Stop after this much team time (default: until stopped).
    #[arg(long, value_parser = parse_dur)]
    pub time_limit: Option<Duration>,
    /// Stop a robot whose commands stop for this long (team time).
    #[arg(long, value_parser = parse_dur, default_value = "1s")]
    pub deadman: Duration,
    /// Draw the run (arena, trajectories) to this SVG file when stopped.
    #[arg(long)]
    pub svg: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct LaunchArgs {
    #[command(flatten)]
    pub mission: MissionArgs,
    /// The team name (default: `launch-<process id>`).
    #[arg(long)]
    pub team: Option<String>,
    /// The team key file (default: a new key in the output directory).
    #[arg(long)]
    pub key: Option<PathBuf>,
    /// Team seconds per wall second.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Where to gather the logs.
    #[arg(long, default_value = "out/launch")]
    pub out: PathBuf,
    /// Kill a robot process at a team time, e.g. `r1@20s` (repeatable).
    #[arg(long)]
    pub kill: Vec<String>,
    /// Give up after this much team time (default: the scenario's limit).
    #[arg(long, value_parser = parse_dur)]
    pub time_limit: Option<Duration>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub tuning: Tuning,
    /// Speak ROS 2 for the robots' bodies, on rmw_zenoh's wire conventions,
    /// in this ROS domain (default 0): `/<robot>/odom`
    /// (`nav_msgs/msg/Odometry`), `/<robot>/scan` (`sensor_msgs/msg/LaserScan`),
    /// `/<robot>/cmd_vel` (`geometry_msgs/msg/Twist`), `/<robot>/bite/status`
    /// (`std_msgs/msg/String`). See docs/ros2.md.
    #[arg(long, value_name = "DOMAIN", num_args = 0..=1, default_missing_value = "0")]
    pub ros2: Option<u32>,
    /// Record every robot's inputs to `<out>/<robot>.inputs` (for `bite
    /// replay`).
    #[arg(long)]
    pub record: bool,
    /// `--mcap FILE`: the team's logs (robots' and the simulator
    /// server's, merged in time order) as one MCAP file when the team is
    /// done. `--foxglove [PORT]`: the team live, from its logs as they grow.
    #[command(flatten)]
    pub viz: crate::viz::VizArgs,
}

#[derive(clap::Args)]
pub struct SubmitArgs {
    /// The behavior graph (YAML) or mission (`.rtcl`) to submit.
    pub graph: PathBuf,
    /// A scenario to send with it (YAML). Default: the one next to the
    /// graph, as `bite run` picks it (physical world first, or the timed one
    /// with `--timed`); none when there is none.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Pick the timed-skill world when choosing the default scenario.
    #[arg(long)]
    pub timed: bool,
    /// A configuration to send with it (YAML).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// A new version of the mission the team is running: each subteam
    /// switches to it at its next safe point (between behaviors, all its
    /// members together) instead of refusing it as busy. Its behaviors are
    /// matched to the running ones by name; a version that cannot replace
    /// the running one is refused with the reason: a `mission_refused`
    /// record in each robot's run log, and `last_rejection` in the status
    /// it publishes on `bite/<team>/status/<robot>`.
    #[arg(long)]
    pub replace: bool,
    /// The submission id (default: a random one).
    #[arg(long)]
    pub id: Option<String>,
    /// The team key file (or `BITE_TEAM_KEY`).
    #[arg(long)]
    pub key: Option<PathBuf>,
    #[command(flatten)]
    pub net: NetArgs,
}

/// The team key: `--key FILE`, else `BITE_TEAM_KEY`. Fails closed.
fn team_key(path: Option<&Path>) -> Result<TeamKey> {
    let text = match path {
        Some(p) => crate::read_input(p)?,
        None => match std::env::var("BITE_TEAM_KEY") {
            Ok(k) => k,
            Err(_) => bail!(
                "no team key: give --key FILE or set BITE_TEAM_KEY (make one with `bite keygen`); \
                 robots never run unauthenticated"
            ),
        },
    };
    TeamKey::from_hex(&text).map_err(|e| {
        let file: Arc<str> =
            Arc::from(path.map_or("BITE_TEAM_KEY".into(), |p| p.display().to_string()));
        crate::bad_input(bite_core::diag::Diagnostics(vec![
            bite_core::diag::Diagnostic::error(
                &file,
                bite_core::diag::Loc::UNKNOWN,
                "bad-key",
                format!("not a team key: {e}"),
            )
            .with_hint("make one with `bite keygen`"),
        ]))
    })
}

fn new_key() -> Result<TeamKey> {
    let mut b = vec![0u8; 32];
    getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("no random source: {e}"))?;
    Ok(TeamKey::new(b)?)
}

/// A flag set by SIGINT / SIGTERM (the handler is installed once per process).
pub(crate) fn stop_flag() -> Result<Arc<AtomicBool>> {
    static STOP: std::sync::OnceLock<Arc<AtomicBool>> = std::sync::OnceLock::new();
    if let Some(s) = STOP.get() {
        return Ok(s.clone());
    }
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::Relaxed))
        .context("installing the signal handler")?;
    Ok(STOP.get_or_init(|| stop).clone())
}

/// `bite keygen`.
pub fn cmd_keygen(output: Option<&Path>) -> Result<ExitCode> {
    let k = new_key()?;
    match output {
        Some(p) => {
            write_secret(p, &k.to_hex())?;
            eprintln!("team key written to {}", p.display());
        }
        None => println!("{}", k.to_hex()),
    }
    Ok(ExitCode::SUCCESS)
}

fn write_secret(p: &Path, text: &str) -> Result<()> {
    if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    let mut o = std::fs::OpenOptions::new();
    o.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.mode(0o600);
    }
    let mut f = o
        .open(p)
        .with_context(|| format!("writing {}", p.display()))?;
    use std::io::Write as _;
    writeln!(f, "{text}").with_context(|| format!("writing {}", p.display()))?;
    Ok(())
}

/// Load a submitted mission against the scenario it carries, else the
/// robot's own (the one it was started with: `--scenario`, or the one next to
/// its graph). A submission with no scenario to a robot that has none is
/// refused with that reason: an empty world would leave the team running
/// for ever.
fn loader(
    base: MissionArgs,
    own: Option<Scenario>,
    robots: Option<usize>,
) -> bite_zenoh::robot::Loader {
    Box::new(
        move |body: &MissionBody, running: Option<&Arc<bite_core::mission::Mission>>| {
            let scenario = match (&body.scenario, &own) {
                (Some(text), _) => Scenario::load_str(
                    &Arc::from(format!("{} (submitted scenario)", body.id)),
                    text,
                )
                .map_err(|d| d.to_string())?,
                (None, Some(s)) => s.clone(),
                (None, None) => {
                    return Err(format!(
                        "submission {} carries no scenario and this robot was started without one: \
                     send one (`bite submit --scenario FILE`, or the `scenario` field) or start \
                     the robots with `--scenario FILE`",
                        body.id
                    ));
                }
            };
            let label = format!("{} (submitted)", body.id);
            let (graph, scenario) = if let Some(src) = &body.rtcl {
                let lib = rtcl::library(base.library.as_deref()).map_err(|e| e.to_string())?;
                let opts = rtcl::options_for(&scenario, robots);
                let compiled =
                    bite_rtcl::compile(&label, src, &lib, &opts).map_err(|d| d.to_string())?;
                let g = compiled
                    .load_graph(&Arc::from(label.as_str()))
                    .map_err(|d| d.to_string())?;
                let s =
                    rtcl::bind_parts(&label, &compiled, &scenario).map_err(|d| d.to_string())?;
                (g, s)
            } else {
                let text = body.graph.as_deref().unwrap_or_default();
                let g = bite_core::graph::load_str(&Arc::from(label.as_str()), text)
                    .map_err(|d| d.to_string())?;
                (g, scenario)
            };
            let graph = match &body.config {
                Some(c) => {
                    let cfg =
                        bite_core::Config::load_str(&Arc::from(format!("{} (config)", body.id)), c)
                            .map_err(|d| d.to_string())?;
                    graph.with_config(&cfg).map_err(|d| d.to_string())?
                }
                None => graph,
            };
            let mission = match running {
                // A new version of the running mission: numbered like it.
                Some(base) => bite_sim::runner::prepare_change(base, &graph, &crate::registry())?,
                None => bite_sim::runner::prepare(&graph, &scenario, robots, &crate::registry())
                    .map_err(|d| d.to_string())?,
            };
            let seed = body.seed.unwrap_or(scenario.seed);
            Ok(Prepared {
                mission,
                scenario,
                seed,
                origin: serde_json::json!({"submitted": body, "base": base.origin(), "robots": robots}),
            })
        },
    )
}

/// `bite robot`: one robot, or several sharing this process's Zenoh
/// session (`--name` repeated), each on its own thread.
pub fn cmd_robot(a: RobotArgs) -> Result<ExitCode> {
    let key = team_key(a.key.as_deref())?;
    let names = &a.name;
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            bail!("--name {n} is given twice");
        }
    }
    let several = names.len() > 1;
    let per_robot = |what: &str, p: &Option<PathBuf>, name: &str| -> Result<Option<PathBuf>> {
        let Some(p) = p else { return Ok(None) };
        let text = p.display().to_string();
        if several && !text.contains("{name}") {
            bail!(
                "{what} {text}: with several robots in one process, name each robot's file \
                 with `{{name}}` (e.g. out/{{name}}.jsonl)"
            );
        }
        Ok(Some(PathBuf::from(text.replace("{name}", name))))
    };
    {
        let mut inputs = a.mission.inputs();
        inputs.extend(a.key.as_deref().map(|k| ("--key", k)));
        let mut files = Vec::new();
        for name in names {
            files.push(("--log", per_robot("--log", &a.log, name)?));
            files.push(("--record", per_robot("--record", &a.record, name)?));
        }
        let outs: Vec<(&str, &Path)> = files
            .iter()
            .filter_map(|(what, p)| p.as_deref().map(|p| (*what, p)))
            .collect();
        crate::outputs::check(&inputs, &outs)?;
    }
    let first = if a.mission.graph.is_some() || a.mission.built_in {
        let (graph, scenario) = a.mission.load()?;
        let mission =
            bite_sim::runner::prepare(&graph, &scenario, a.mission.robots, &crate::registry())
                .map_err(crate::bad_input)?;
        let roster = mission.graph().roster();
        if let Some(n) = names.iter().find(|n| roster.find(n).is_none()) {
            bail!(
                "robot `{n}` is not on the roster of mission `{}` ({})",
                mission.graph().name(),
                (roster.iter().map(|(_, r)| r.name.clone()))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        let seed = a.mission.seed.unwrap_or(scenario.seed);
        Some(Prepared {
            mission,
            scenario,
            seed,
            origin: serde_json::json!({ "args": a.mission.origin() }),
        })
    } else {
        None
    };
    let own = match &first {
        Some(p) => Some(p.scenario.clone()),
        None => a.mission.own_scenario()?,
    };
    let stop = stop_flag()?;
    let mut robots = Vec::new();
    for name in names {
        let opts = RobotOptions {
            team: a.net.team.clone(),
            name: name.clone(),
            key: key.clone(),
            net: a.net.options(),
            speed: a.speed,
            start_at_us: a.start_at.map(|ms| ms.saturating_mul(1000)),
            log: per_robot("--log", &a.log, name)?,
            exit_when_done: a.exit_when_done,
            time_limit: a.time_limit,
            gather_timeout: a.gather_timeout,
            status_period: Duration::from_millis(500),
            record: per_robot("--record", &a.record, name)?,
            ros2: a
                .ros2
                .map(|domain| bite_zenoh::ros2::Ros2Options { domain }),
            publish: a.frames.publish(),
        };
        let prepared = first.as_ref().map(|p| Prepared {
            mission: p.mission.clone(),
            scenario: p.scenario.clone(),
            seed: p.seed,
            origin: p.origin.clone(),
        });
        let load = loader(a.mission.clone(), own.clone(), a.mission.robots);
        robots.push((opts, prepared, load));
        if first.is_none() {
            eprintln!(
                "robot {name} of team {}: waiting for a mission on bite/{}/mission",
                a.net.team, a.net.team
            );
        }
    }
    let outcomes: Vec<(String, Result<bite_zenoh::robot::Outcome, _>)> = if several {
        let session = a.net.options().open()?;
        let outs = std::thread::scope(|s| {
            let handles: Vec<_> = robots
                .into_iter()
                .map(|(opts, prepared, load)| {
                    let (session, stop) = (&session, stop.clone());
                    let name = opts.name.clone();
                    let h = std::thread::Builder::new()
                        .name(format!("robot {name}"))
                        .spawn_scoped(s, move || {
                            bite_zenoh::robot::run_on(session, opts, prepared, load, stop)
                        });
                    (name, h)
                })
                .collect();
            handles
                .into_iter()
                .map(|(name, h)| {
                    let out = match h {
                        Ok(h) => h.join().unwrap_or_else(|_| {
                            Err(bite_zenoh::robot::RobotError::Options(
                                "the robot's thread panicked".into(),
                            ))
                        }),
                        Err(e) => Err(bite_zenoh::robot::RobotError::Options(format!(
                            "cannot start its thread: {e}"
                        ))),
                    };
                    (name, out)
                })
                .collect()
        });
        {
            use bite_zenoh::zenoh::Wait as _;
            let _ = session.close().wait();
        }
        outs
    } else {
        robots
            .into_iter()
            .map(|(opts, prepared, load)| {
                let name = opts.name.clone();
                (
                    name,
                    bite_zenoh::robot::run(opts, prepared, load, stop.clone()),
                )
            })
            .collect()
    };
    let mut all = true;
    let mut failed = None;
    for (name, out) in outcomes {
        match out {
            Ok(out) => {
                all &= out.completed;
                eprintln!(
                    "robot {name}: {} ({} frames accepted, {} rejected)",
                    if out.completed {
                        "mission completed"
                    } else {
                        "stopped before completing"
                    },
                    out.auth.accepted,
                    out.auth.rejected_total()
                );
            }
            Err(e) => {
                if several {
                    eprintln!("robot {name}: {e}");
                }
                failed.get_or_insert(anyhow::anyhow!("robot {name}: {e}"));
            }
        }
    }
    if let Some(e) = failed {
        return Err(e);
    }
    Ok(if all {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// `bite sim serve`.
pub fn cmd_serve(a: ServeArgs) -> Result<ExitCode> {
    let outs: Vec<(&str, &Path)> = [("--log", &a.log), ("--svg", &a.svg)]
        .into_iter()
        .filter_map(|(what, p)| p.as_deref().map(|p| (what, p)))
        .collect();
    crate::outputs::check(&a.mission.inputs(), &outs)?;
    let (graph, scenario) = a.mission.load()?;
    let mission =
        bite_sim::runner::prepare(&graph, &scenario, a.mission.robots, &crate::registry())
            .map_err(crate::bad_input)?;
    let seed = a.mission.seed.unwrap_or(scenario.seed);
    let stop = stop_flag()?;
    let opts = bite_zenoh::server::ServerOptions {
        team: a.net.team.clone(),
        net: a.net.options(),
        speed: a.speed,
        start_at_us: a.start_at.map(|ms| ms.saturating_mul(1000)),
        time_limit: a.time_limit,
        deadman: a.deadman,
        log: a.log.clone(),
        ros2: a
            .ros2
            .map(|domain| bite_zenoh::ros2::Ros2Options { domain }),
    };
    eprintln!(
        "simulator server for team {}: scenario `{}`, {} robots, seed {seed}",
        a.net.team,
        scenario.name,
        mission.graph().roster().len()
    );
    let report = bite_zenoh::server::serve(mission.graph(), &scenario, seed, &opts, stop)?;
    if let Some(svg) = &a.svg {
        let g = mission.graph();
        let names: Vec<String> = g.roster().iter().map(|(_, r)| r.name.clone()).collect();
        let behaviors = |b: bite_core::ids::BehaviorId| g.name_of(b).to_string();
        let text = bite_sim::physics::svg::draw(
            &report.world,
            &bite_sim::physics::svg::Labels {
                title: format!("{} over Zenoh, team {}", g.name(), a.net.team),
                robots: &names,
                behaviors: &behaviors,
                at: None,
            },
        );
        std::fs::write(svg, text).with_context(|| format!("writing {}", svg.display()))?;
    }
    eprintln!(
        "simulator server stopped at {:.1} s: commands {:?}, {} rejected",
        report.end.as_secs_f64(),
        report.commands,
        report.rejected
    );
    Ok(ExitCode::SUCCESS)
}

/// `bite submit`.
pub fn cmd_submit(a: SubmitArgs) -> Result<ExitCode> {
    use bite_zenoh::zenoh::Wait;
    let key = team_key(a.key.as_deref())?;
    let read = |p: &Path| crate::read_input(p);
    let text = read(&a.graph)?;
    let scenario = submitted_scenario(&a)?;
    let id = match a.id {
        Some(id) => id,
        None => {
            let mut b = [0u8; 8];
            getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("no random source: {e}"))?;
            bite_zenoh::auth::to_hex(&b)
        }
    };
    let is_rtcl = rtcl::is_mission(&a.graph);
    let body = MissionBody {
        id: id.clone(),
        issued_at: unix_micros() / 1000,
        graph: (!is_rtcl).then(|| text.clone()),
        rtcl: is_rtcl.then_some(text),
        config: a.config.as_deref().map(read).transpose()?,
        scenario: scenario.as_deref().map(read).transpose()?,
        seed: None,
        replace: a.replace,
    };
    // An input error (exit 2), said before anything is sent.
    let refuse = |why: String| {
        eprintln!("error: {why}; nothing was sent");
        anyhow::Error::new(Reported(2))
    };
    if let Some(w) = check_submission(&body, rtcl::is_mission(&a.graph)).map_err(refuse)? {
        eprintln!("warning: {w}");
    }
    let sub = bite_zenoh::wire::sign_submission(&key, &a.net.team, &body);
    let bytes = serde_json::to_vec(&sub)?;
    let most = bite_zenoh::wire::MAX_SUBMISSION_BYTES;
    if bytes.len() > most {
        return Err(refuse(format!(
            "the submission is {} bytes; robots take at most {most} (1 MiB) and would drop it \
             unread",
            bytes.len()
        )));
    }
    let session = a.net.options().open()?;
    // Give the session a moment to reach its peers before the put.
    std::thread::sleep(Duration::from_millis(500));
    session
        .put(bite_zenoh::Keys::new(&a.net.team).mission(), bytes)
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
    std::thread::sleep(Duration::from_millis(200));
    let _ = session.close().wait();
    println!("{id}");
    Ok(ExitCode::SUCCESS)
}

/// What a robot will make of a submission, checked before it is sent. A
/// graph (YAML) or configuration that does not parse is refused: no robot
/// could read it. With a scenario (and not a new version of a running
/// mission, which a robot numbers against the mission it runs), the
/// mission is also loaded as a robot with the default command library,
/// team size and protocols loads it; since the robots may have been
/// started with their own (`--library`, `--robots`, `--protocols`), what
/// fails there is a warning (`Ok(Some(..))`), and the mission is sent.
fn check_submission(body: &MissionBody, rtcl: bool) -> Result<Option<String>, String> {
    let refused = |e: String| format!("robots would refuse this mission: {e}");
    if let Some(text) = body.graph.as_ref().filter(|_| !rtcl) {
        let label = format!("{} (submitted)", body.id);
        let graph = bite_core::graph::load_str(&Arc::from(label.as_str()), text)
            .map_err(|d| refused(d.to_string()))?;
        if let Some(c) = &body.config {
            let cfg = bite_core::Config::load_str(&Arc::from(format!("{} (config)", body.id)), c)
                .map_err(|d| refused(d.to_string()))?;
            graph
                .with_config(&cfg)
                .map_err(|d| refused(d.to_string()))?;
        }
    }
    if body.scenario.is_some() && !body.replace {
        return Ok(loader(MissionArgs::default(), None, None)(body, None)
            .err()
            .map(|e| {
                format!(
                    "a robot with the default command library, team size and protocols would \
                     refuse this mission ({e}); sent anyway, for robots started with their own"
                )
            }));
    }
    Ok(None)
}

/// The scenario `bite submit` sends: the one given, else the one next to
/// the graph (as `bite run` picks it), else none (the robots then use their
/// own, or refuse the mission if they have none).
fn submitted_scenario(a: &SubmitArgs) -> Result<Option<PathBuf>> {
    if a.scenario.is_some() {
        return Ok(a.scenario.clone());
    }
    let rtcl = rtcl::is_mission(&a.graph);
    let physical = crate::sibling_scenario(&a.graph, true);
    let timed = crate::sibling_scenario(&a.graph, false);
    let guess = if (rtcl || !a.timed) && physical.exists() {
        physical
    } else {
        timed
    };
    if guess.exists() {
        eprintln!("scenario: {}", guess.display());
        Ok(Some(guess))
    } else {
        eprintln!(
            "note: no --scenario and {} does not exist: the robots run the mission in their own world \
             (a robot started without one refuses it)",
            guess.display()
        );
        Ok(None)
    }
}

/// Free TCP ports on 127.0.0.1 for robots to listen on (see
/// [`bite_zenoh::net::free_ports`]: below the ports outgoing connections
/// take, so that a teammate's connection cannot take one first).
pub fn free_ports(n: usize) -> Result<Vec<u16>> {
    bite_zenoh::net::free_ports(n).context("finding free ports")
}

struct Proc {
    /// Its name: its robot's, or its robots' joined by `+`.
    name: String,
    /// The robots it runs.
    robots: Vec<String>,
    child: Child,
    exit: Option<std::process::ExitStatus>,
    killed_at: Option<f64>,
    /// Team time at which it was stopped as unresponsive: a robot of it
    /// was presumed lost by teammates that completed, and stayed silent
    /// (see [`crate::unresponsive`]).
    unresponsive_at: Option<f64>,
}

impl Drop for Proc {
    /// Whatever happens to the launcher (an error, a panic), no child is
    /// left behind: one still running is asked to stop, then killed.
    fn drop(&mut self) {
        if self.exit.is_none() {
            terminate(&mut self.child);
        }
    }
}

/// `bite launch`: the whole team on this machine.
pub fn cmd_launch(a: LaunchArgs) -> Result<ExitCode> {
    let (summary, ok) = launch(&a, false)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "team {}: mission `{}` on scenario `{}` over Zenoh",
            summary["team"].as_str().unwrap_or("?"),
            summary["graph"].as_str().unwrap_or("?"),
            summary["scenario"].as_str().unwrap_or("?")
        );
        for r in summary["robots"].as_array().into_iter().flatten() {
            let state = if r["completed"] == true {
                "COMPLETED"
            } else if !r["killed_at"].is_null() {
                "KILLED"
            } else if !r["unresponsive_at"].is_null() {
                "UNRESPONSIVE"
            } else {
                "INCOMPLETE"
            };
            let lost: Vec<&str> = (r["lost"].as_array().into_iter().flatten())
                .filter_map(|x| x.as_str())
                .collect();
            println!(
                "  {:<6} {:<10} exit {:<4} {}{}",
                r["robot"].as_str().unwrap_or("?"),
                state,
                r["exit"].as_i64().map_or("-".into(), |c| c.to_string()),
                r["completed_at"]
                    .as_f64()
                    .map_or(String::new(), |t| format!("at {t:.1} s")),
                if lost.is_empty() {
                    String::new()
                } else {
                    format!("; presumed lost: {}", lost.join(", "))
                },
            );
        }
        let dis = summary["disagreements"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        println!(
            "  joint decisions: {} instances, {} disagreements",
            summary["joint_decisions"],
            dis.len()
        );
        for d in &dis {
            println!("    {}", d.as_str().unwrap_or("?"));
        }
        println!(
            "  invariants: {} checked over {} records, {} violations",
            summary["invariants"]["checked"]
                .as_array()
                .map_or(0, Vec::len),
            summary["records_checked"],
            summary["invariants"]["violations"]
        );
        for v in summary["violations"].as_array().into_iter().flatten() {
            println!("    VIOLATION {}", v.as_str().unwrap_or("?"));
        }
        println!("  logs: {}", summary["logs"].as_str().unwrap_or("?"));
    }
    Ok(
        if summary["invariants"]["violations"].as_u64().unwrap_or(0) > 0 {
            ExitCode::from(bite_sim::summary::EXIT_VIOLATION)
        } else if ok {
            ExitCode::SUCCESS
        } else {
            ExitCode::from(Reported(1).0)
        },
    )
}

/// Run a team on this machine until its robots end; the summary (also
/// written to `<out>/summary.json`) and whether every robot not killed
/// completed with its teammates agreeing on every joint decision.
pub fn launch(a: &LaunchArgs, quiet: bool) -> Result<(serde_json::Value, bool)> {
    let (graph, scenario) = a.mission.load()?;
    let mission =
        bite_sim::runner::prepare(&graph, &scenario, a.mission.robots, &crate::registry())
            .map_err(crate::bad_input)?;
    let graph = mission.graph().clone();
    let n = graph.roster().len();
    let names: Vec<String> = graph.roster().iter().map(|(_, r)| r.name.clone()).collect();
    let physical = scenario.physics.is_some();
    let mut kills: BTreeMap<String, f64> = BTreeMap::new();
    for k in &a.kill {
        let (who, at) = k
            .split_once('@')
            .with_context(|| format!("--kill {k}: expected ROBOT@TIME, e.g. r1@20s"))?;
        if !names.iter().any(|n| n == who) {
            bail!(
                "--kill {k}: no robot `{who}` on the roster ({})",
                names.join(", ")
            );
        }
        let at = parse_dur(at).map_err(|e| anyhow::anyhow!("--kill {k}: {e}"))?;
        kills.insert(who.to_string(), at.as_secs_f64());
    }
    let team = a
        .team
        .clone()
        .unwrap_or_else(|| format!("launch-{}", std::process::id()));
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let key_path = match &a.key {
        Some(p) => {
            team_key(Some(p))?;
            p.clone()
        }
        None => {
            let p = a.out.join("team.key");
            write_secret(&p, &new_key()?.to_hex())?;
            p
        }
    };
    let limit = a.time_limit.unwrap_or(scenario.time_limit);
    let exe = std::env::current_exe().context("finding the bite executable")?;
    // Robots per process: r0..r(N-1) in the first, and so on.
    let groups: Vec<Vec<String>> = names
        .chunks(a.tuning.per_process.max(1))
        .map(<[String]>::to_vec)
        .collect();
    let ports = free_ports(groups.len() + 1)?;
    let ep = |i: usize| format!("tcp/127.0.0.1:{}", ports[i]);
    // Logs of an earlier launch in the same directory are not this team's.
    for p in std::iter::once(a.out.join("server.jsonl"))
        .chain(names.iter().map(|n| a.out.join(format!("{n}.jsonl"))))
    {
        match std::fs::remove_file(&p) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("removing the old log {}", p.display()));
            }
            _ => {}
        }
    }
    // The live view first: the team starts once a viewer is connected.
    let live_args = crate::viz::VizArgs {
        mcap: None,
        foxglove: a.viz.foxglove,
        pace: a.viz.pace,
    };
    let mut live = crate::viz::Viz::start(&live_args, &format!("bite launch {team}"), false)?;
    let mut tails = crate::viz::Tails::new(
        std::iter::once(a.out.join("server.jsonl"))
            .chain(names.iter().map(|n| a.out.join(format!("{n}.jsonl"))))
            .collect(),
    );
    // Everyone starts its clock at the same moment, once all are up.
    let start_ms = unix_micros() / 1000 + 2500;
    let stop = stop_flag()?;
    let mut procs: Vec<Proc> = Vec::new();
    let spawn = |name: &str, robots: &[String], args: Vec<String>| -> Result<Proc> {
        let out = std::fs::File::create(a.out.join(format!("{name}.log")))?;
        let err = out.try_clone()?;
        let mut cmd = std::process::Command::new(&exe);
        cmd.args(&args)
            .stdin(Stdio::null())
            .stdout(Stdio::from(out))
            .stderr(Stdio::from(err));
        if !robots.is_empty()
            && let Some(rt) = a.tuning.zenoh_runtime.env()
        {
            cmd.env("ZENOH_RUNTIME", rt);
        }
        let child = cmd.spawn().with_context(|| format!("starting {name}"))?;
        Ok(Proc {
            name: name.to_string(),
            robots: robots.to_vec(),
            child,
            exit: None,
            killed_at: None,
            unresponsive_at: None,
        })
    };
    let common = |v: &mut Vec<String>| {
        v.extend([
            "--team".into(),
            team.clone(),
            "--speed".into(),
            a.speed.to_string(),
        ]);
        if let Some(d) = a.ros2 {
            v.extend(["--ros2".into(), d.to_string()]);
        }
        v.extend(["--start-at".into(), start_ms.to_string()]);
    };
    let mut server = if physical {
        let mut args = vec!["sim".to_string(), "serve".into()];
        args.extend(a.mission.to_args());
        common(&mut args);
        args.extend(["--listen".into(), ep(0)]);
        args.extend([
            "--log".into(),
            a.out.join("server.jsonl").display().to_string(),
        ]);
        args.extend([
            "--svg".into(),
            a.out.join("world.svg").display().to_string(),
        ]);
        // The server stops by itself a little after the robots' limit.
        args.extend([
            "--time-limit".into(),
            format!("{}s", limit.as_secs_f64() + 10.0 * a.speed),
        ]);
        Some(spawn("server", &[], args)?)
    } else {
        None
    };
    for (k, group) in groups.iter().enumerate() {
        let mut args = vec!["robot".to_string()];
        for name in group {
            args.extend(["--name".into(), name.clone()]);
        }
        // One robot: its own name; several: `{name}`, which each makes its own.
        let name = if group.len() == 1 {
            group[0].clone()
        } else {
            "{name}".to_string()
        };
        args.extend(a.mission.to_args());
        common(&mut args);
        args.extend(["--listen".into(), ep(k + 1)]);
        // Each pair connects once: to the server and to the robots before.
        for j in 0..=k {
            if j > 0 || physical {
                args.extend(["--connect".into(), ep(j)]);
            }
        }
        args.extend(["--key".into(), key_path.display().to_string()]);
        args.extend([
            "--log".into(),
            a.out.join(format!("{name}.jsonl")).display().to_string(),
        ]);
        args.extend([
            "--exit-when-done".into(),
            "--time-limit".into(),
            format!("{}s", limit.as_secs_f64()),
        ]);
        if a.record {
            args.extend([
                "--record".into(),
                a.out.join(format!("{name}.inputs")).display().to_string(),
            ]);
        }
        args.extend(["--frames".into(), a.tuning.frames.name().into()]);
        procs.push(spawn(&group.join("+"), group, args)?);
    }
    if !quiet {
        eprintln!(
            "team {team}: {n} robots in {} processes{} on 127.0.0.1, logs in {}",
            procs.len(),
            if physical {
                " and the simulator server"
            } else {
                ""
            },
            a.out.display()
        );
    }
    // Where an outside monitor joins the team (`bite studio`).
    let endpoints: Vec<String> = (0..=groups.len())
        .filter(|&i| i > 0 || physical)
        .map(|i| format!("--connect {}", ep(i)))
        .collect();
    eprintln!("monitor: bite studio --team {team} {}", endpoints.join(" "));
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(limit.as_secs().max(1))
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} team time {pos}/{len} s [{bar:30}] {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let wall_limit =
        Duration::from_secs_f64(limit.as_secs_f64() / a.speed) + Duration::from_secs(20);
    let began = unix_micros();
    let mut watch = crate::unresponsive::Watch::default();
    loop {
        let t = (unix_micros() as f64 / 1000.0 - start_ms as f64) / 1000.0 * a.speed;
        // What the logs say: who completed, whom its teammates presume lost.
        let records = tails.poll();
        let now_us = unix_micros();
        for r in &records {
            watch.see(r, now_us);
        }
        if let Some(v) = live.as_mut() {
            for r in &records {
                v.record(r);
            }
        }
        bar.set_position(t.max(0.0) as u64);
        for p in procs.iter_mut() {
            if p.exit.is_none() {
                p.exit = p.child.try_wait()?;
            }
            // Killing a robot kills its process, and so every robot in it.
            if p.exit.is_none()
                && p.killed_at.is_none()
                && (p.robots.iter()).any(|r| kills.get(r).is_some_and(|at| t >= *at))
            {
                let _ = p.child.kill();
                p.killed_at = Some(t);
                bar.println(format!("killed {} at team time {t:.1} s", p.name));
            }
        }
        // Robots presumed lost by teammates that completed, silent ever
        // since (frozen, hung): stopped after a grace period, not waited
        // for until the wall limit.
        let running: Vec<Option<&[String]>> = (procs.iter())
            .map(|p| (p.exit.is_none() && p.killed_at.is_none()).then_some(p.robots.as_slice()))
            .collect();
        for i in watch.silent(&running, now_us) {
            let p = &mut procs[i];
            let _ = p.child.kill();
            p.unresponsive_at = Some(t);
            p.exit = p.child.wait().ok();
            bar.println(format!(
                "stopped {} at team time {t:.1} s: presumed lost by its teammates, which completed, \
                 and silent for {} s",
                p.name,
                crate::unresponsive::GRACE.as_secs()
            ));
        }
        let done = procs.iter().filter(|p| p.exit.is_some()).count();
        bar.set_message(format!("{done}/{} robot processes ended", procs.len()));
        if done == procs.len() {
            break;
        }
        // Without its world, a physical team cannot go on.
        let server_died = match server.as_mut() {
            Some(s) if s.exit.is_none() => {
                s.exit = s.child.try_wait()?;
                s.exit.is_some()
            }
            _ => false,
        };
        if server_died {
            bar.println(format!(
                "the simulator server exited early (see {})",
                a.out.join("server.log").display()
            ));
        }
        if server_died
            || stop.load(Ordering::Relaxed)
            || Duration::from_micros(unix_micros().saturating_sub(began)) > wall_limit
        {
            bar.println("stopping the team");
            for p in procs.iter_mut().filter(|p| p.exit.is_none()) {
                terminate(&mut p.child);
                p.exit = p.child.try_wait()?;
            }
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    bar.finish_and_clear();
    let server_exit = server.as_mut().map(|s| {
        if s.exit.is_none() {
            terminate(&mut s.child);
            s.exit = s.child.try_wait().ok().flatten();
        }
        s.exit
    });
    for p in procs.iter_mut() {
        if p.exit.is_none() {
            p.exit = p.child.wait().ok();
        }
    }
    // Gather the logs and check agreement on joint decisions.
    let logs: Vec<(String, Vec<serde_json::Value>)> = names
        .iter()
        .map(|n| Ok((n.clone(), read_jsonl(&a.out.join(format!("{n}.jsonl")))?)))
        .collect::<Result<_>>()?;
    let registry = crate::registry();
    let agreement =
        bite_zenoh::agreement::check(&logs, |p| registry.get(p).is_some_and(|p| p.communicates()));
    // The same invariants every simulated run is held to, over the logs. A
    // robot stopped as unresponsive ran nothing after its last record (it
    // was frozen or hung): crashed there, as a killed one.
    let stopped: Vec<&str> = procs
        .iter()
        .filter(|p| p.killed_at.is_some() || p.unresponsive_at.is_some())
        .flat_map(|p| p.robots.iter().map(String::as_str))
        .collect();
    let (violations, records_checked) = bite_sim::check::check_logs(&mission, &logs, &stopped);
    let invariants = bite_sim::check::Invariants::of(&violations);
    let robots: Vec<serde_json::Value> = procs
        .iter()
        .flat_map(|p| p.robots.iter().map(move |name| (p, name)))
        .map(|(p, name)| {
            let log = &logs.iter().find(|(n, _)| n == name).map(|(_, l)| l.as_slice()).unwrap_or(&[]);
            let completed = log.iter().any(|r| r["event"] == "mission_completed");
            let lost: Vec<&serde_json::Value> = log
                .iter()
                .filter(|r| r["event"] == "member_lost")
                .map(|r| &r["member"])
                .collect();
            // Frames refused as forged, malformed or replayed: not its own
            // echoes, nor a teammate's that came while this robot was still
            // starting (`before-mission`, counted in its log: robots of a
            // launch do not start at the same instant).
            let rejected: u64 = log
                .iter()
                .rev()
                .find(|r| r["event"] == "run_finished")
                .and_then(|r| r["auth"]["rejected"].as_object())
                .map_or(0, |m| {
                    m.iter()
                        .filter(|(k, _)| !matches!(k.as_str(), "own" | "before-mission"))
                        .filter_map(|(_, v)| v.as_u64())
                        .sum()
                });
            json!({
                "robot": name,
                "process": p.name,
                "exit": p.exit.and_then(|e| e.code()),
                "killed_at": p.killed_at,
                "unresponsive_at": p.unresponsive_at,
                "completed": completed,
                "completed_at": log.iter().find(|r| r["event"] == "mission_completed").map(|r| r["t"].clone()),
                "lost": lost,
                "frames_rejected": rejected,
            })
        })
        .collect();
    let survivors_completed = robots
        .iter()
        .filter(|r| r["killed_at"].is_null())
        .all(|r| r["completed"] == true);
    // Robots stopped as unresponsive before they completed.
    let unresponsive: Vec<serde_json::Value> = (robots.iter())
        .filter(|r| !r["unresponsive_at"].is_null() && r["completed"] != true)
        .map(|r| r["robot"].clone())
        .collect();
    let summary = json!({
        "team": team,
        "graph": graph.name(),
        "scenario": scenario.name,
        "speed": a.speed,
        "processes": procs.len(),
        "tuning": a.tuning.label(),
        "robots": robots,
        "server": server_exit.map(|e| e.and_then(|e| e.code())),
        "completed": survivors_completed,
        "unresponsive": unresponsive,
        "joint_decisions": agreement.decisions,
        "disagreements": agreement.disagreements,
        "silent_splits": agreement.splits,
        "invariants": invariants,
        "records_checked": records_checked,
        "violations": violations.iter().map(ToString::to_string).collect::<Vec<_>>(),
        "logs": a.out.display().to_string(),
    });
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    if let Some(p) = &a.viz.mcap {
        let mut all = vec![read_jsonl(&a.out.join("server.jsonl"))?];
        all.extend(logs.into_iter().map(|(_, l)| l));
        let (records, messages) = crate::viz::write_mcap(all, p)?;
        if !quiet {
            eprintln!(
                "mcap: {} ({records} records, {messages} messages)",
                p.display()
            );
        }
    }
    if let Some(mut v) = live {
        for r in tails.poll() {
            v.record(&r);
        }
        v.finish()?;
    }
    let ok = survivors_completed && agreement.disagreements.is_empty() && violations.is_empty();
    Ok((summary, ok))
}

/// Ask a child to stop (SIGTERM), then kill it if it does not within 5 s.
fn terminate(c: &mut Child) {
    if let Ok(Some(_)) = c.try_wait() {
        return;
    }
    let pid = nix::unistd::Pid::from_raw(c.id() as i32);
    let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
    for _ in 0..100 {
        if let Ok(Some(_)) = c.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = c.kill();
    let _ = c.wait();
}

pub fn read_jsonl(p: &Path) -> Result<Vec<serde_json::Value>> {
    let text = match std::fs::read_to_string(p) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e).with_context(|| format!("reading {}", p.display())),
    };
    // A killed process may leave a torn last line: skip what does not parse.
    Ok(text
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect())
}

/// The team size a record's origin gives (`robots`, absent or null for the
/// mission's own), held to the bounds of `--robots`: a record is a file
/// anyone may edit, and a team of 10^11 robots would eat memory without end.
fn origin_robots(v: &serde_json::Value, file: &Path) -> Result<Option<usize>> {
    if v.is_null() {
        return Ok(None);
    }
    let n = v.as_u64().with_context(|| {
        format!(
            "{}: the record's team size `robots` is {v}, not a number of robots",
            file.display()
        )
    })?;
    parse_robots(&n.to_string()).map(Some).map_err(|e| {
        anyhow::anyhow!(
            "{}: the record's team size `robots` is {n}: {e}",
            file.display()
        )
    })
}

/// `bite replay FILE`: re-run a robot's mind from its recorded inputs and
/// say whether every output is identical.
pub fn cmd_replay(file: &Path) -> Result<ExitCode> {
    use std::io::BufRead as _;
    let f = std::fs::File::open(file).with_context(|| format!("reading {}", file.display()))?;
    let mut r = std::io::BufReader::new(f);
    let header = bite_agent::record::header(&mut r)
        .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    let origin = &header["origin"];
    let prepared = if origin.get("submitted").is_some() {
        let body: MissionBody = serde_json::from_value(origin["submitted"].clone())
            .with_context(|| format!("{}: the recorded submission", file.display()))?;
        let base = MissionArgs::from_origin(&origin["base"], file)?;
        let robots = origin_robots(&origin["robots"], file)?;
        let own = base.own_scenario()?;
        loader(base, own, robots)(&body, None).map_err(|e| anyhow::anyhow!("{e}"))?
    } else if origin.get("args").is_some() {
        let args = MissionArgs::from_origin(&origin["args"], file)?;
        let (graph, scenario) = args.load()?;
        let mission = bite_sim::runner::prepare(&graph, &scenario, args.robots, &crate::registry())
            .map_err(crate::bad_input)?;
        let seed = args.seed.unwrap_or(scenario.seed);
        Prepared {
            mission,
            scenario,
            seed,
            origin: origin.clone(),
        }
    } else {
        anyhow::bail!(
            "{}: the record does not say what mission it ran",
            file.display()
        );
    };
    let name = header["robot"].as_str().unwrap_or_default();
    let graph = prepared.mission.graph().clone();
    let me = graph.roster().find(name).with_context(|| {
        format!(
            "{}: robot `{name}` is not on the mission's roster",
            file.display()
        )
    })?;
    let seed = header["seed"].as_u64().unwrap_or(prepared.seed);
    let mut agent =
        bite_agent::agent::Agent::new(prepared.mission.clone(), &prepared.scenario, me, seed)
            .map_err(crate::bad_input)?;
    let _ = r.fill_buf();
    let out = bite_agent::record::replay(&mut r, &mut agent)
        .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    match out.first_difference {
        None => {
            println!(
                "identical ({} inputs of robot {name}{})",
                out.inputs,
                if out.truncated {
                    "; the record ends in a cut line: the robot was stopped while writing it"
                } else {
                    ""
                }
            );
            Ok(ExitCode::SUCCESS)
        }
        Some(d) => {
            println!(
                "differs at line {} (t = {:.6} s): recorded {} outputs ({}), replayed {} ({})",
                d.line,
                d.t as f64 / 1e6,
                d.recorded.0,
                d.recorded.1,
                d.replayed.0,
                d.replayed.1
            );
            for o in d.replayed.2.iter().take(20) {
                println!("  {o}");
            }
            Ok(ExitCode::from(1))
        }
    }
}
