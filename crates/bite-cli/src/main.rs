//! `bite` — run, check and draw BITE multi-robot missions.

use anyhow::{Context, Result};

mod anim;
mod benchkit;
mod plot;
mod rtcl;
mod team;
mod unresponsive;
mod zbench;
use bite_core::diag::{Diagnostic, Diagnostics};
use bite_core::graph::BehaviorGraph;
use bite_core::{Config, Mission};
use bite_sim::runner::{Progress, RunOptions};
use bite_sim::{Scenario, prepare, run};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

/// `println!` that ends the program quietly when the reader of standard
/// output has gone away (`bite check g.yaml | head`) instead of panicking.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let mut o = std::io::stdout().lock();
        if let Err(e) = writeln!(o, $($t)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
        }
    }};
}

/// `print!` with the same behavior as [`outln!`].
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let mut o = std::io::stdout().lock();
        if let Err(e) = write!(o, $($t)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
        }
    }};
}

mod experiment;
mod globwalk;
mod lapbench;
mod outputs;
mod stats;
mod studio;
mod sweep;
mod tune;
mod viz;

/// The formation example, built in so that `bite run` works anywhere.
const FORMATION_GRAPH: &str = include_str!("../../../examples/formation.yaml");
const FORMATION_SCENARIO: &str = include_str!("../../../examples/scenarios/formation.yaml");
const FORMATION_PHYSICS: &str = include_str!("../../../examples/scenarios/formation-physics.yaml");

#[derive(Parser)]
#[command(
    name = "bite",
    version,
    about = "BITE teamwork engine: run, check and draw multi-robot missions",
    long_about = "BITE (Bar Ilan Teamwork Engine) in Rust. A team of robots coordinates itself: \
                  you write a behavior graph, BITE finds where the robots must agree and runs \
                  the protocol you bind at each of those points."
)]
struct Cli {
    /// Protocol files (interaction behaviors written as behavior graphs)
    /// to load beside the built-in ones, in order; every command can bind
    /// them. Give a team's robot processes the same files.
    #[arg(long = "protocols", global = true, value_name = "FILE")]
    protocols: Vec<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

/// The registry of this process: the library, the shipped graph protocols
/// and the `--protocols` files (loaded once, in `main`).
static REGISTRY: std::sync::OnceLock<bite_core::interaction::Registry> = std::sync::OnceLock::new();

/// The `--protocols` files of this process (set once, in `main`): inputs
/// that no output may overwrite (see [`outputs::check`]).
static PROTOCOL_FILES: std::sync::OnceLock<Vec<PathBuf>> = std::sync::OnceLock::new();

/// The `--protocols` files given.
fn protocol_files() -> &'static [PathBuf] {
    PROTOCOL_FILES.get().map_or(&[], Vec::as_slice)
}

#[derive(Subcommand)]
enum Cmd {
    /// Run a mission in the simulator (default: the built-in formation example).
    Run(RunArgs),
    /// Validate a behavior graph and list its coordination points with their protocols.
    Check {
        /// The behavior graph (YAML).
        graph: PathBuf,
        /// A configuration file binding protocols to points.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Print a behavior graph as Graphviz DOT (sequential and decomposition edges, points).
    Graph {
        /// The behavior graph (YAML).
        graph: PathBuf,
        /// A configuration file binding protocols to points.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Graphviz DOT output (the default).
        #[arg(long, default_value_t = true)]
        dot: bool,
        /// SVG instead, drawn without Graphviz (the picture `bite studio`
        /// shows: the decomposition top-down, chains left to right).
        #[arg(long)]
        svg: bool,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Compile a mission in the robot team command language (`.rtcl`) into
    /// a behavior graph: prints the graph (YAML, or `--dot`), and with
    /// `--world` the skills, beliefs and targets it gives the scenario.
    Compile {
        /// The mission.
        mission: PathBuf,
        /// Graphviz DOT of the generated graph instead of YAML.
        #[arg(long)]
        dot: bool,
        /// Also print the world parts (skills, beliefs, targets), in the
        /// scenario format.
        #[arg(long)]
        world: bool,
        /// The command library (default: the built-in one).
        #[arg(long)]
        library: Option<PathBuf>,
        /// Take the mission origin and team size from this scenario.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Team size (default: the scenario's, else 2).
        #[arg(long, value_parser = parse_robots)]
        robots: Option<usize>,
        /// Where the mission's (0, 0) is, `x,y` in metres (default: the
        /// scenario's, else 0,0).
        #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
        origin: Option<[f64; 2]>,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// List the interaction protocols that can be bound to points.
    Protocols,
    /// One robot as its own process: its kernel, world model and skills,
    /// talking to its teammates over Zenoh (authenticated with the team key).
    Robot(team::RobotArgs),
    /// The simulator as a server over Zenoh.
    Sim {
        #[command(subcommand)]
        which: SimCmd,
    },
    /// Start a whole team on this machine (robot processes, and the
    /// simulator server for a physical world) over Zenoh on 127.0.0.1,
    /// gather their logs, check they agree, and stop them.
    Launch(team::LaunchArgs),
    /// Submit a mission (graph or `.rtcl`) to a running team, signed with the team key.
    Submit(team::SubmitArgs),
    /// Make a new team key (hex) for `--key`.
    Keygen {
        /// Write it to this file (mode 0600) instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// The fault matrix: graphs × configurations × worlds × fault classes ×
    /// seeds, the invariant checker on every run, on every core; a table
    /// per fault class and the command that replays every failing run.
    Sweep(sweep::SweepArgs),
    /// Compare configurations on missions, as the BITE paper's Table II
    /// does: runs on every core (resumable), `runs.csv`, Figure-3-style
    /// charts and box plots (SVG, PNG), and a report with pairwise
    /// comparisons (`docs/experiments.md`).
    Experiment(experiment::ExperimentArgs),
    /// Search the protocol bindings of every point of a mission for the
    /// best configuration on an objective (racing over seeds), and compare
    /// it with the shipped configurations on held-out seeds.
    Tune(tune::TuneArgs),
    /// Re-run a robot's mind from the inputs `bite robot --record` (or
    /// `bite launch --record`) wrote, and say whether every output is
    /// identical (exit 0) or where it first differs (exit 1).
    Replay {
        /// The record (`<robot>.inputs`).
        file: PathBuf,
    },
    /// Run logs: convert them to other formats.
    Log {
        #[command(subcommand)]
        which: LogCmd,
    },
    /// The studio: a web editor for missions and graphs (command sidebar,
    /// diagnostics as you type, the graph drawn, Run), a live monitor of
    /// the team (a run it started, or a Zenoh team with `--connect`) and
    /// replay of run logs; served on 127.0.0.1.
    Studio(studio::StudioArgs),
    /// Whole-system benchmarks.
    Bench {
        #[command(subcommand)]
        which: BenchCmd,
    },
}

#[derive(Subcommand)]
enum LogCmd {
    /// Convert run logs (JSON lines: a simulated run's, or a launched
    /// team's robot and server logs, merged in time order) to an MCAP file
    /// that Foxglove and Lichtblick open (see `bite run --mcap`).
    Convert {
        /// The run logs.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The MCAP file to write.
        #[arg(short, long)]
        output: PathBuf,
    },
}

#[derive(Subcommand)]
enum SimCmd {
    /// Own the physical world of a scenario: publish each robot's sensor
    /// readings and apply its velocity commands over Zenoh.
    Serve(team::ServeArgs),
}

#[derive(clap::Args)]
struct RunArgs {
    /// The behavior graph (YAML), or a mission in the robot team command
    /// language (`.rtcl`, compiled first). Default: the built-in formation
    /// example.
    graph: Option<PathBuf>,
    /// The command library for `.rtcl` missions (default: the built-in one).
    #[arg(long)]
    library: Option<PathBuf>,
    /// A configuration file binding protocols to points (e.g. a Table II row).
    #[arg(long)]
    config: Option<PathBuf>,
    /// The scenario (timed-skill world). Default: `scenarios/<graph file
    /// name without extension>.yaml` next to the graph, if it exists.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Seed (default: the scenario's).
    #[arg(long)]
    seed: Option<u64>,
    /// Team size (default: the scenario's, else the graph's).
    #[arg(long, value_parser = parse_robots)]
    robots: Option<usize>,
    /// Stop after this much simulated time (e.g. `120s`).
    #[arg(long, value_parser = parse_dur)]
    time_limit: Option<Duration>,
    /// Where to write the JSON-lines run log (default: `out/<graph>-seed<seed>.jsonl`).
    #[arg(long)]
    log: Option<PathBuf>,
    /// Also log every message a robot sends (`message` records: sender,
    /// recipients, protocol instance, kind, bytes), to trace a
    /// conversation.
    #[arg(long)]
    log_messages: bool,
    /// Print the summary as JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Use the timed-skill world (discrete events only, no physics) when
    /// picking the default scenario: `scenarios/<graph>.yaml` instead of
    /// `scenarios/<graph>-physics.yaml`.
    #[arg(long)]
    timed: bool,
    /// Draw the run (arena, objects, trajectories coloured by behavior,
    /// formation links) to this SVG file. Physical world only.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Write an animation as numbered SVG frames into this directory.
    #[arg(long)]
    frames: Option<PathBuf>,
    /// Write an animation as a looping GIF (one frame every `--every`
    /// simulated seconds, shown ten times faster).
    #[arg(long)]
    gif: Option<PathBuf>,
    /// Seconds of simulated time between frames of `--frames` and
    /// `--gif`: at least 0.01 (a GIF's shortest delay, shown ten times
    /// faster). At most 10,000 frames are drawn: a run that would take
    /// more draws its first 10,000, with a warning.
    #[arg(long, default_value_t = 1.0, value_parser = parse_every)]
    every: f64,
    /// A fault laid over the scenario (repeatable): `loss=0.2`, `dup=0.3`,
    /// `jitter=200ms`, `partition=r0|r1,r2@10s+15s`, `oneway=r0>r1@5s+3s`,
    /// `hold=12s+2s`, `pause=r1@12s+5s`, `crash=r2@20s`,
    /// `restart=r1@15s+2s`, `skew=r1:1.1:2s`, `inject=100ms`. What `bite
    /// sweep` prints to replay a run.
    #[arg(long = "fault", value_parser = parse_fault)]
    faults: Vec<bite_sim::fault::Fault>,
    #[command(flatten)]
    viz: viz::VizArgs,
}

/// The shortest `--every`, seconds: a GIF's delays are whole hundredths of
/// a second, shown ten times faster than simulated time.
const MIN_EVERY: f64 = 0.01;

/// The most frames `--frames` and `--gif` draw: a run's animation is one
/// picture per frame (each with every trail so far), and more would fill a
/// disk rather than show a run. A run that would take more draws its first
/// ones, with a warning.
const MAX_FRAMES: usize = 10_000;

/// How many frames `--frames` and `--gif` draw of a run that ended at
/// `end` seconds, one every `every` seconds, and how many the whole run
/// would take: at most [`MAX_FRAMES`] are drawn (the first ones).
fn frame_count(end: f64, every: f64) -> (usize, usize) {
    let all = (end / every).floor().min(usize::MAX as f64 / 2.0) as usize + 1;
    (all.min(MAX_FRAMES), all)
}

/// `--every`: seconds between frames, at least [`MIN_EVERY`].
fn parse_every(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= MIN_EVERY => Ok(v),
        Ok(_) => Err(format!(
            "`{s}`: frames are at least {MIN_EVERY} s of simulated time apart"
        )),
        Err(_) => Err(format!("`{s}` is not a number of seconds")),
    }
}

fn parse_fault(s: &str) -> Result<bite_sim::fault::Fault, String> {
    bite_sim::fault::Fault::parse(s)
}

#[derive(Subcommand)]
enum BenchCmd {
    /// The physical world: the shipped scenarios (formation, box push,
    /// coverage), then teams of N robots sweeping an arena (`--mission`)
    /// for a simulated minute (`--seconds`): wall time, physics steps per
    /// second, real-time factor.
    Sim {
        /// Team sizes of the runs at scale.
        #[arg(long, value_delimiter = ',', value_parser = parse_robots, default_values_t = [10usize, 100, 1000, 10000])]
        robots: Vec<usize>,
        /// Simulated seconds of each run at scale.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// The mission of the runs at scale: `coverage` (each robot sweeps
        /// the cell it starts in) or `crossing` (each starts about half the
        /// arena away from its cell: the team crosses the arena first, its
        /// bodies mixing).
        #[arg(long, value_enum, default_value_t = SimMission::Coverage)]
        mission: SimMission,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        scaling: benchkit::Scaling,
        /// Print the results as JSON (`{"rows": [...]}`) instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Every protocol of the library, one decision each in the
    /// discrete-event runner: messages and rounds per decision by team size;
    /// then the auction and token passing at scale (robots × tasks).
    Protocols {
        /// Team sizes.
        #[arg(long, value_delimiter = ',', default_values_t = [3usize, 10, 100])]
        robots: Vec<usize>,
        /// Robots and tasks of the large auction / token-passing runs (0: skip).
        #[arg(long, default_value_t = 1000)]
        large: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print the results as JSON (`{"rows": [...], "large": [...]}`)
        /// instead of tables.
        #[arg(long)]
        json: bool,
    },
    /// `alloc.optimal`'s assignment solver on cost matrices read from a
    /// file: per matrix, the best-of-K solve time and the total cost, as
    /// JSON (`scripts/lap_vs_scipy.py` compares it with SciPy). The file:
    /// one or more matrices, each a line `rows cols` then rows × cols
    /// little-endian f64, row-major.
    Lap {
        /// The matrices.
        #[arg(long)]
        input: PathBuf,
        /// Solves per matrix; the best time is reported.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
    },
    /// Decision latency over Zenoh between robot processes on 127.0.0.1
    /// (sync.leader, sync.vote, alloc.auction), next to a raw Zenoh
    /// ping-pong round trip measured in the same run.
    Zenoh {
        /// Team sizes (robot processes).
        #[arg(long, value_delimiter = ',', value_parser = parse_robots, default_values_t = [3usize, 10])]
        robots: Vec<usize>,
        /// Decisions per protocol and team size.
        #[arg(long, default_value_t = 20)]
        decisions: usize,
        /// Ping-pong round trips.
        #[arg(long, default_value_t = 500)]
        pings: usize,
        /// Where to keep the teams' logs and the results.
        #[arg(long, default_value = "out/bench-zenoh")]
        out: PathBuf,
        /// Print the results as JSON (`{"rtt_median_us": ..., "rows":
        /// [...]}`) instead of a table.
        #[arg(long)]
        json: bool,
        /// The variant measured (as `bite launch` takes it).
        #[command(flatten)]
        tuning: team::Tuning,
    },
    /// The echo side of `bench zenoh`'s ping-pong.
    #[command(hide = true)]
    Pong {
        #[arg(long)]
        team: String,
        #[arg(long)]
        listen: String,
    },
    /// A whole team in the timed-skill world: simulated seconds per wall
    /// second, robot-ticks per second and peak memory, for each team size,
    /// thread count and repetition.
    Team {
        /// Team sizes (one run each, or `--repeat` runs).
        #[arg(long, num_args = 1.., value_delimiter = ',', default_values_t = [1000usize], value_parser = parse_robots)]
        robots: Vec<usize>,
        /// The behavior graph (default: the built-in formation example).
        #[arg(long)]
        graph: Option<PathBuf>,
        /// The scenario (default: the built-in formation scenario).
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// A configuration file.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Simulated time to run (default: until the mission completes).
        #[arg(long, value_parser = parse_dur)]
        sim_time: Option<Duration>,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        scaling: benchkit::Scaling,
        /// Print the result as JSON (`{"rows": [{"robots": N,
        /// "real_time_factor": F, ...}]}`) instead of text.
        #[arg(long)]
        json: bool,
    },
}

fn parse_dur(s: &str) -> Result<Duration, String> {
    bite_core::time::parse_duration(s)
}

/// `x,y` in metres.
fn parse_point(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [x, y] = parts.as_slice() else {
        return Err(format!("expected `x,y` (two numbers, metres), found `{s}`"));
    };
    let num = |t: &str| {
        t.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("`{t}` is not a number (in `{s}`)"))
    };
    Ok([num(x)?, num(y)?])
}

fn parse_robots(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("a team needs at least one robot".into()),
        Ok(n) if n > bite_core::graph::MAX_ROBOTS => {
            Err(format!("at most {} robots", bite_core::graph::MAX_ROBOTS))
        }
        Ok(n) => Ok(n),
        Err(_) => Err(format!("expected a number of robots, found `{s}`")),
    }
}

/// The most worker threads `--jobs` may ask for: far more than any machine
/// this runs on has cores (a run is CPU-bound, so more threads than cores
/// buys nothing), and few enough that starting them cannot exhaust the
/// process's threads or memory.
pub(crate) const MAX_JOBS: usize = 1024;

/// `--jobs`: a number of worker threads, 1 to [`MAX_JOBS`].
pub(crate) fn parse_jobs(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("at least one thread".into()),
        Ok(n) if n > MAX_JOBS => Err(format!(
            "at most {MAX_JOBS} threads (a run uses one core; more threads than cores are no faster)"
        )),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("expected a number of threads, found `{s}`")),
    }
}

/// The default of `--jobs`: every core (at most [`MAX_JOBS`]).
pub(crate) fn default_jobs() -> usize {
    std::thread::available_parallelism()
        .map_or(1, std::num::NonZeroUsize::get)
        .min(MAX_JOBS)
}

/// A failure that has already been explained to the user.
#[derive(Debug)]
struct Reported(u8);
impl std::fmt::Display for Reported {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "exit {}", self.0)
    }
}
impl std::error::Error for Reported {}

fn print_diags(d: &[Diagnostic]) {
    for x in d {
        eprintln!("{x}");
    }
}

/// Print diagnostics and turn them into an exit code 2 failure.
fn bad_input(d: Diagnostics) -> anyhow::Error {
    print_diags(&d.0);
    let n = d.errors().count();
    eprintln!("{n} error{} found", if n == 1 { "" } else { "s" });
    anyhow::Error::new(Reported(2))
}

/// Read a user file as every input is read (bounded, invalid UTF-8
/// located); a failure is printed as a diagnostic and exits 2.
fn read_input(path: &Path) -> Result<String> {
    let file: Arc<str> = Arc::from(path.display().to_string());
    bite_core::yaml::read_text(&file, path).map_err(bad_input)
}

fn load_graph(path: Option<&Path>, config: Option<&Path>) -> Result<BehaviorGraph> {
    let graph = match path {
        Some(p) => bite_core::graph::load(p).map_err(bad_input)?,
        None => bite_core::graph::load_str(
            &Arc::from("examples/formation.yaml (built in)"),
            FORMATION_GRAPH,
        )
        .map_err(bad_input)?,
    };
    print_diags(graph.warnings());
    with_config(graph, config)
}

/// A mission file given where a graph is expected (`check`, `graph`): its
/// graph, compiled with the default options.
fn load_graph_or_mission(path: &Path, config: Option<&Path>) -> Result<BehaviorGraph> {
    if rtcl::is_mission(path) {
        let lib = rtcl::library(None)?;
        let compiled = rtcl::compile(path, &lib, &bite_rtcl::CompileOptions::default())?;
        with_config(rtcl::graph(path, &compiled)?, config)
    } else {
        load_graph(Some(path), config)
    }
}

/// The scenario's `mission_changes:`, loaded and numbered (version 1, 2,
/// ...), each aligned to the one before it. A version that cannot replace
/// the one before is an input error at the scenario line that names it.
pub(crate) fn scenario_changes(
    scenario: &Scenario,
    mission: &Arc<Mission>,
) -> Result<Vec<bite_sim::runner::Change>> {
    use bite_agent::scenario::MissionChange;
    let here = Path::new(&*scenario.file);
    let mut base = mission.clone();
    let mut out = Vec::new();
    for (i, c) in scenario.mission_changes.iter().enumerate() {
        let graph = MissionChange::path(here, &c.graph);
        let config = c.config.as_ref().map(|x| MissionChange::path(here, x));
        let g = load_graph_or_mission(&graph, config.as_deref())?;
        let next = bite_sim::runner::prepare_change(&base, &g, &registry()).map_err(|why| {
            bad_input(bite_core::diag::Diagnostics(vec![
                bite_core::diag::Diagnostic::error(
                    &scenario.file,
                    c.loc,
                    "change-refused",
                    format!(
                        "{} cannot replace the running mission: {why}",
                        graph.display()
                    ),
                ),
            ]))
        })?;
        out.push(bite_sim::runner::Change {
            at: c.at,
            version: i as u32 + 1,
            mission: next.clone(),
            source: graph.display().to_string(),
        });
        base = next;
    }
    Ok(out)
}

fn with_config(graph: BehaviorGraph, config: Option<&Path>) -> Result<BehaviorGraph> {
    match config {
        Some(c) => {
            let cfg = Config::load(c).map_err(bad_input)?;
            graph.with_config(&cfg).map_err(bad_input)
        }
        None => Ok(graph),
    }
}

/// `scenarios/<stem>-physics.yaml` (or `<stem>.yaml` for the timed world)
/// next to a graph or mission file.
pub(crate) fn sibling_scenario(p: &Path, physical: bool) -> PathBuf {
    let stem = p
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let dir = p.parent().unwrap_or(Path::new("."));
    if physical {
        dir.join("scenarios").join(format!("{stem}-physics.yaml"))
    } else {
        dir.join("scenarios").join(format!("{stem}.yaml"))
    }
}

fn load_scenario(
    graph_path: Option<&Path>,
    scenario: Option<&Path>,
    graph: &BehaviorGraph,
    timed: bool,
) -> Result<Scenario> {
    if let Some(s) = scenario {
        return Scenario::load(s).map_err(bad_input);
    }
    match graph_path {
        None if timed => Scenario::load_str(
            &Arc::from("examples/scenarios/formation.yaml (built in)"),
            FORMATION_SCENARIO,
        )
        .map_err(bad_input),
        None => Scenario::load_str(
            &Arc::from("examples/scenarios/formation-physics.yaml (built in)"),
            FORMATION_PHYSICS,
        )
        .map_err(bad_input),
        Some(p) => {
            let physical = sibling_scenario(p, true);
            let timed_guess = sibling_scenario(p, false);
            let guess = if !timed && physical.exists() {
                physical
            } else {
                timed_guess
            };
            if guess.exists() {
                eprintln!("scenario: {}", guess.display());
                Scenario::load(&guess).map_err(bad_input)
            } else {
                eprintln!(
                    "note: no scenario given and {} does not exist: using an empty timed world \
                     (skills take no time and set nothing) for graph `{}`",
                    guess.display(),
                    graph.name()
                );
                Ok(Scenario::default())
            }
        }
    }
}

fn registry() -> bite_core::interaction::Registry {
    REGISTRY.get_or_init(bite_protocols::registry).clone()
}

/// True when `path` is a protocol file (a top-level `protocol:` key). Only a
/// regular file is peeked at: a device or a FIFO can be read once only (a
/// FIFO's writer is gone after the first reader), so it goes straight to the
/// command that reads it, which refuses it at the size cap.
fn is_protocol_file(path: &Path) -> bool {
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return false;
    }
    let file: Arc<str> = Arc::from(path.display().to_string());
    bite_core::yaml::read_text(&file, path)
        .is_ok_and(|text| bite_core::yaml::lines(&text).any(|l| l.starts_with("protocol:")))
}

fn load_protocol(path: &Path) -> Result<bite_protocols::graphdef::GraphProtocol> {
    bite_protocols::graphdef::GraphProtocol::load(path, &registry()).map_err(bad_input)
}

/// `bite check` on a protocol file: load it on its own and describe it.
fn cmd_check_protocol(path: &Path) -> Result<ExitCode> {
    let p = load_protocol(path)?;
    use bite_core::interaction::Protocol as _;
    let r = bite_protocols::graphdef::Registered(std::sync::Arc::new(p));
    let d = r.def();
    outln!(
        "protocol `{}` ({} point, graph-defined, deadline {:.1}s): {}",
        r.name(),
        r.kind(),
        r.default_deadline().as_secs_f64(),
        r.summary()
    );
    if let Some(t) = d.twin() {
        outln!("  mirrors `{t}`");
    }
    outln!("  {}", d.outline());
    outln!(
        "  bind it: `{{ protocol: {} }}` at a {} point",
        r.name(),
        r.kind()
    );
    Ok(ExitCode::SUCCESS)
}

/// The graph and the scenario of a run: a graph file (or the built-in
/// formation example) with its scenario, or a mission compiled against its
/// scenario (`bite run`, `bite robot`, `bite sim serve`, `bite launch`).
fn load_team(
    graph: Option<&Path>,
    library: Option<&Path>,
    config: Option<&Path>,
    scenario: Option<&Path>,
    robots: Option<usize>,
    timed: bool,
) -> Result<(BehaviorGraph, Scenario)> {
    Ok(match graph {
        Some(p) if rtcl::is_mission(p) => {
            // The scenario first: it says where the mission's (0, 0) is
            // and how many robots there are.
            let scenario = match scenario {
                Some(s) => Scenario::load(s).map_err(bad_input)?,
                None => {
                    let guess = sibling_scenario(p, true);
                    if !guess.exists() {
                        eprintln!(
                            "error: a mission runs in a physical world, and {} does not exist",
                            guess.display()
                        );
                        eprintln!("  = hint: give one with --scenario FILE");
                        return Err(anyhow::Error::new(Reported(2)));
                    }
                    eprintln!("scenario: {}", guess.display());
                    Scenario::load(&guess).map_err(bad_input)?
                }
            };
            let lib = rtcl::library(library)?;
            let compiled = rtcl::compile(p, &lib, &rtcl::options_for(&scenario, robots))?;
            let graph = with_config(rtcl::graph(p, &compiled)?, config)?;
            let scenario = rtcl::bind(p, &compiled, &scenario)?;
            (graph, scenario)
        }
        _ => {
            let g = load_graph(graph, config)?;
            let scenario = load_scenario(graph, scenario, &g, timed)?;
            (g, scenario)
        }
    })
}

fn cmd_run(a: RunArgs) -> Result<ExitCode> {
    let (graph, mut scenario) = load_team(
        a.graph.as_deref(),
        a.library.as_deref(),
        a.config.as_deref(),
        a.scenario.as_deref(),
        a.robots,
        a.timed,
    )?;
    if !a.faults.is_empty() {
        scenario = bite_sim::fault::apply_all(&scenario, &a.faults);
    }
    if (a.svg.is_some() || a.frames.is_some() || a.gif.is_some()) && scenario.physics.is_none() {
        eprintln!(
            "error: --svg, --frames and --gif draw the physical world, and scenario `{}` is a timed world",
            scenario.name
        );
        eprintln!("  = hint: give a scenario with `world: physics`, or leave out --timed");
        return Ok(ExitCode::from(2));
    }
    if !(a.every.is_finite() && a.every >= MIN_EVERY) {
        anyhow::bail!("--every must be at least {MIN_EVERY} seconds");
    }
    let mission = prepare(&graph, &scenario, a.robots, &registry()).map_err(bad_input)?;
    if !a.faults.is_empty() {
        // A fault that names a robot the team lacks is an input error: the
        // team as it runs (`--robots`, or the scenario's `robots:`), not
        // the graph's own roster.
        scenario.resolve(mission.graph()).map_err(bad_input)?;
    }
    let seed = a.seed.unwrap_or(scenario.seed);
    let log_path = a.log.unwrap_or_else(|| {
        let mut name = mission.graph().name().to_string();
        if let Some(c) = mission.graph().config_name() {
            name.push('-');
            name.push_str(c);
        }
        PathBuf::from("out").join(format!("{name}-seed{seed}.jsonl"))
    });
    {
        let mut inputs: Vec<(&str, &Path)> = Vec::new();
        let named = [
            ("graph", &a.graph),
            ("--library", &a.library),
            ("--config", &a.config),
            ("--scenario", &a.scenario),
        ];
        for (what, p) in &named {
            if let Some(p) = p {
                inputs.push((*what, p.as_path()));
            }
        }
        let mut outs: Vec<(&str, &Path)> = vec![("--log", log_path.as_path())];
        for (what, p) in [
            ("--svg", &a.svg),
            ("--gif", &a.gif),
            ("--mcap", &a.viz.mcap),
        ] {
            if let Some(p) = p {
                outs.push((what, p.as_path()));
            }
        }
        outputs::check(&inputs, &outs)?;
    }
    if let Some(dir) = log_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let file = std::fs::File::create(&log_path)
        .with_context(|| format!("creating the run log {}", log_path.display()))?;
    let mut writer = std::io::BufWriter::new(file);
    let limit = a.time_limit.unwrap_or(scenario.time_limit);
    let bar = ProgressBar::new(limit.as_secs().max(1));
    bar.set_style(
        ProgressStyle::with_template("{spinner} simulated {pos}/{len} s [{bar:30}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut on_progress = |p: Progress| {
        bar.set_position(p.now.as_secs_f64() as u64);
        bar.set_message(format!("{}/{} robots done", p.finished, p.robots));
    };
    let changes = scenario_changes(&scenario, &mission)?;
    let mut viz = viz::Viz::start(
        &a.viz,
        &format!("bite run {}", mission.graph().name()),
        true,
    )?;
    let mut on_record = |r: &serde_json::Value| {
        if let Some(v) = viz.as_mut() {
            v.record(r)
        }
    };
    let report = run(
        mission.clone(),
        &scenario,
        RunOptions {
            seed: Some(seed),
            time_limit: a.time_limit,
            log: Some(&mut writer),
            record: false,
            progress: Some(&mut on_progress),
            changes,
            watch: (a.viz.mcap.is_some() || a.viz.foxglove.is_some()).then_some(
                bite_sim::runner::Watch {
                    on_record: &mut on_record,
                    poses_every: Duration::from_millis(100),
                },
            ),
            pool: None,
            batch_from: None,
            batch_most: None,
            log_messages: a.log_messages,
        },
    )
    .map_err(bad_input)?;
    bar.finish_and_clear();
    drop(writer);
    print_diags(&report.warnings);
    let pictures = draw_pictures(&report, &mission, &a.svg, &a.frames, &a.gif, a.every)?;
    let recorded = match viz {
        Some(v) => v.finish()?,
        None => Vec::new(),
    };
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report.summary)?);
    } else {
        out!("{}", report.summary);
        outln!("  run log          {}", log_path.display());
        for p in &pictures {
            outln!("  picture          {p}");
        }
        for p in &recorded {
            outln!("  mcap             {p}");
        }
        if report.summary.outcome != bite_sim::summary::Outcome::Completed
            || !report.violations.is_empty()
        {
            // Everything that chose this run: the replay line runs it
            // again (a timed run replayed without `--timed` ran in the
            // physical world).
            let mut extra = String::new();
            if let Some(l) = &a.library {
                extra.push_str(&format!(" --library {}", l.display()));
            }
            if a.timed {
                extra.push_str(" --timed");
            }
            if let Some(c) = &a.config {
                extra.push_str(&format!(" --config {}", c.display()));
            }
            if let Some(t) = a.time_limit {
                extra.push_str(&format!(" --time-limit {}s", t.as_secs_f64()));
            }
            for f in &a.faults {
                extra.push_str(&format!(" --fault '{f}'"));
            }
            outln!(
                "  replay           bite run {}{extra} --seed {seed}",
                describe_inputs(a.graph.as_deref(), &mission, &scenario)
            );
        }
        for v in &report.violations {
            outln!("  VIOLATION        {v}");
        }
    }
    Ok(ExitCode::from(run_exit_code(&report)))
}

/// The exit code of a simulated run: its outcome's, or
/// [`bite_sim::summary::EXIT_VIOLATION`] if it broke an invariant.
fn run_exit_code(report: &bite_sim::runner::RunReport) -> u8 {
    if report.violations.is_empty() {
        report.summary.outcome.exit_code()
    } else {
        bite_sim::summary::EXIT_VIOLATION
    }
}

/// Write the run's pictures; returns what was written.
fn draw_pictures(
    report: &bite_sim::runner::RunReport,
    mission: &Mission,
    svg: &Option<PathBuf>,
    frames: &Option<PathBuf>,
    gif: &Option<PathBuf>,
    every: f64,
) -> Result<Vec<String>> {
    let Some(world) = &report.world else {
        return Ok(Vec::new());
    };
    let g = mission.graph();
    let robots: Vec<String> = (0..g.roster().len() as u32)
        .map(|r| g.roster().name(bite_core::ids::RobotId(r)).to_string())
        .collect();
    let behaviors = |b: bite_core::ids::BehaviorId| g.name_of(b).to_string();
    let s = &report.summary;
    let title = |t: f64| {
        format!(
            "{}{} on {} — seed {}, t = {t:.1} s{}",
            s.graph,
            s.config
                .as_ref()
                .map(|c| format!(" ({c})"))
                .unwrap_or_default(),
            s.scenario,
            s.seed,
            s.world
                .as_ref()
                .and_then(|w| w.goal.as_ref().map(|g| (g, w.goal_met_at)))
                .map(|(g, at)| match at {
                    Some(at) if at <= t => format!(", {g} at {at:.1} s"),
                    _ => format!(", {g}: not yet"),
                })
                .unwrap_or_default()
        )
    };
    let mut written = Vec::new();
    let end = report.end.as_secs_f64();
    if let Some(p) = svg {
        let doc = bite_sim::physics::svg::draw(
            world,
            &bite_sim::physics::svg::Labels {
                title: title(end),
                robots: &robots,
                behaviors: &behaviors,
                at: None,
            },
        );
        std::fs::write(p, doc).with_context(|| format!("writing {}", p.display()))?;
        written.push(p.display().to_string());
    }
    if frames.is_some() || gif.is_some() {
        let every = if every > 0.0 { every } else { 1.0 };
        let (count, all) = frame_count(end, every);
        if count < all {
            eprintln!(
                "warning: --every {every} s over the run's {end:.2} s is {all} frames; drawing the \
                 first {count} (to t = {:.2} s): give a larger --every to draw the whole run",
                (count - 1) as f64 * every
            );
        }
        if let Some(dir) = frames {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        // Ten times faster than simulated time.
        let mut anim = match gif {
            Some(p) => Some(anim::GifWriter::create(p, (every * 100.0).round() as u32)?),
            None => None,
        };
        // One frame at a time: a long run does not hold them all.
        for k in 0..count {
            let t = (k as f64 * every).min(end);
            let doc = bite_sim::physics::svg::draw(
                world,
                &bite_sim::physics::svg::Labels {
                    title: title(t),
                    robots: &robots,
                    behaviors: &behaviors,
                    at: Some(t),
                },
            );
            if let Some(dir) = frames {
                let p = dir.join(format!("frame-{k:05}.svg"));
                std::fs::write(&p, &doc).with_context(|| format!("writing {}", p.display()))?;
            }
            if let Some(a) = anim.as_mut() {
                a.push(&doc)?;
            }
        }
        drop(anim);
        for p in [frames, gif].into_iter().flatten() {
            written.push(format!("{} ({count} frames)", p.display()));
        }
    }
    Ok(written)
}

/// The arguments that reproduce a run, for the replay hint: the graph or
/// mission file as the user named it (a compiled mission's graph is named
/// `<file> (compiled)`, which is not a path), then the scenario.
fn describe_inputs(graph: Option<&Path>, mission: &Mission, scenario: &Scenario) -> String {
    let built_in = |f: &str| f.ends_with("(built in)") || f.starts_with('<');
    let mut parts = Vec::new();
    let g = mission.graph();
    if let Some(path) = graph {
        parts.push(path.display().to_string());
    }
    if !built_in(&scenario.file) {
        parts.push(format!("--scenario {}", scenario.file));
    }
    parts.push(format!("--robots {}", g.roster().len()));
    parts.join(" ")
}

fn cmd_check(graph: &Path, config: Option<&Path>) -> Result<ExitCode> {
    let g = load_graph_or_mission(graph, config)?;
    let mission = Mission::new(g, &registry()).map_err(bad_input)?;
    let g = mission.graph();
    outln!("{g}");
    if let Some(c) = g.config_name() {
        outln!("configuration `{c}`");
    }
    let points = mission.points();
    outln!(
        "{} coordination points (found from the graph's structure):",
        points.len()
    );
    outln!(
        "  {:<26} {:<10} {:<16} {:>9}  where",
        "point",
        "kind",
        "protocol",
        "deadline"
    );
    for (p, b) in points {
        let beh = g.behavior(p.behavior);
        let why = match p.kind {
            bite_core::msg::Kind::Sync => format!(
                "after `{}`: choose among {}",
                beh.name,
                beh.next
                    .iter()
                    .map(|n| format!("`{}`", g.name_of(*n)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            bite_core::msg::Kind::Allocate => format!(
                "`{}` splits its team among {}",
                beh.name,
                beh.children
                    .iter()
                    .map(|n| format!("`{}`", g.name_of(*n)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            bite_core::msg::Kind::Terminate => {
                format!("team behavior `{}` ends together", beh.name)
            }
        };
        outln!(
            "  {:<26} {:<10} {:<16} {:>8.1}s  {}",
            p.name,
            p.kind.to_string(),
            b.protocol.name(),
            b.deadline.as_secs_f64(),
            why
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn cmd_graph(
    graph: &Path,
    config: Option<&Path>,
    output: Option<&Path>,
    svg: bool,
) -> Result<ExitCode> {
    if let Some(out) = output {
        let mut inputs = vec![("graph", graph)];
        inputs.extend(config.map(|c| ("--config", c)));
        outputs::check(&inputs, &[("--output", out)])?;
    }
    if config.is_none() && is_protocol_file(graph) {
        if svg {
            eprintln!(
                "error: --svg draws behavior graphs; {} is a protocol file",
                graph.display()
            );
            eprintln!("  = hint: draw it with Graphviz: bite graph FILE | dot -Tsvg");
            return Ok(ExitCode::from(2));
        }
        let dot = load_protocol(graph)?.to_dot();
        match output {
            Some(p) => {
                std::fs::write(p, dot).with_context(|| format!("writing {}", p.display()))?
            }
            None => out!("{dot}"),
        }
        return Ok(ExitCode::SUCCESS);
    }
    let g = load_graph_or_mission(graph, config)?;
    let mission = Mission::new(g, &registry()).map_err(bad_input)?;
    let protocol = |b, k| {
        mission
            .bound(b, k)
            .map_or("?".into(), |x: &bite_core::mission::Bound| {
                x.protocol.name().to_string()
            })
    };
    let dot = if svg {
        bite_core::graph::svg::to_svg_with(mission.graph(), &protocol)
    } else {
        bite_core::graph::dot::to_dot_with(mission.graph(), &protocol)
    };
    match output {
        Some(p) => std::fs::write(p, dot).with_context(|| format!("writing {}", p.display()))?,
        None => out!("{dot}"),
    }
    Ok(ExitCode::SUCCESS)
}

struct CompileArgs<'a> {
    mission: &'a Path,
    dot: bool,
    world: bool,
    library: Option<&'a Path>,
    scenario: Option<&'a Path>,
    robots: Option<usize>,
    origin: Option<[f64; 2]>,
    output: Option<&'a Path>,
}

fn cmd_compile(a: CompileArgs<'_>) -> Result<ExitCode> {
    if let Some(out) = a.output {
        let mut inputs = vec![("mission", a.mission)];
        inputs.extend(a.library.map(|p| ("--library", p)));
        inputs.extend(a.scenario.map(|p| ("--scenario", p)));
        outputs::check(&inputs, &[("--output", out)])?;
    }
    let mut opts = match a.scenario {
        Some(s) => rtcl::options_for(&Scenario::load(s).map_err(bad_input)?, a.robots),
        None => bite_rtcl::CompileOptions::default(),
    };
    if let Some(r) = a.robots {
        opts.robots = r;
    }
    if let Some(o) = a.origin {
        opts.origin = o;
    }
    let lib = rtcl::library(a.library)?;
    let compiled = rtcl::compile(a.mission, &lib, &opts)?;
    // Check the generated graph as any graph is checked.
    let g = rtcl::graph(a.mission, &compiled)?;
    let mut text = if a.dot {
        let mission = Mission::new(g, &registry()).map_err(bad_input)?;
        bite_core::graph::dot::to_dot_with(mission.graph(), &|b, k| {
            mission
                .bound(b, k)
                .map_or("?".into(), |x| x.protocol.name().to_string())
        })
    } else {
        compiled.graph()
    };
    if a.world && !a.dot {
        text.push_str("---\n");
        text.push_str(&compiled.world_yaml());
    }
    match a.output {
        Some(p) => std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))?,
        None => out!("{text}"),
    }
    Ok(ExitCode::SUCCESS)
}

fn cmd_protocols() -> ExitCode {
    let r = registry();
    outln!(
        "{:<18} {:<10} {:<6} {:<8} {:<6} summary",
        "name",
        "kind",
        "comm",
        "aliases",
        "graph"
    );
    for p in r.iter() {
        outln!(
            "{:<18} {:<10} {:<6} {:<8} {:<6} {}",
            p.name(),
            p.kind().to_string(),
            if p.communicates() { "yes" } else { "no" },
            p.aliases().join(","),
            if p.source().is_some() { "yes" } else { "-" },
            p.summary()
        );
    }
    outln!(
        "graph = written as a behavior graph (a protocol file: `bite check FILE`, `bite graph FILE`; docs/protocols.md)"
    );
    ExitCode::SUCCESS
}

const BOX_PUSH_GRAPH: &str = include_str!("../../../examples/box-push.yaml");
const BOX_PUSH_PHYSICS: &str = include_str!("../../../examples/scenarios/box-push-physics.yaml");
const COVERAGE_GRAPH: &str = include_str!("../../../examples/coverage.yaml");
const COVERAGE_PHYSICS: &str = include_str!("../../../examples/scenarios/coverage-physics.yaml");

/// The mission of `bite bench sim`'s runs at scale.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum SimMission {
    /// Each robot sweeps the cell it starts in.
    Coverage,
    /// Each robot starts about half the arena away from its cell.
    Crossing,
}

impl SimMission {
    fn name(self) -> &'static str {
        match self {
            SimMission::Coverage => "coverage",
            SimMission::Crossing => "crossing",
        }
    }
}

/// What `bite bench sim` runs.
struct SimBench<'a> {
    robots: &'a [usize],
    seconds: f64,
    mission: SimMission,
    seed: u64,
    scaling: &'a benchkit::Scaling,
    json: bool,
}

#[allow(clippy::disallowed_methods)] // a benchmark measures wall time
fn cmd_bench_sim(b: SimBench<'_>) -> Result<ExitCode> {
    let (robots, seconds) = (b.robots, b.seconds);
    let mut cases: Vec<(String, String, String)> = vec![
        (
            "formation".into(),
            FORMATION_GRAPH.into(),
            FORMATION_PHYSICS.into(),
        ),
        (
            "box-push".into(),
            BOX_PUSH_GRAPH.into(),
            BOX_PUSH_PHYSICS.into(),
        ),
        (
            "coverage".into(),
            COVERAGE_GRAPH.into(),
            COVERAGE_PHYSICS.into(),
        ),
    ];
    let mission_name = b.mission.name();
    for n in robots {
        let (g, s) = match b.mission {
            SimMission::Coverage => bite_agent::swarm::coverage_mission(*n, seconds),
            SimMission::Crossing => bite_agent::swarm::crossing_mission(*n, seconds),
        };
        cases.push((format!("{mission_name} {n}"), g, s));
    }
    let first_at_scale = cases.len() - robots.len();
    let mut rows = Vec::new();
    if !b.json {
        outln!(
            "| run | robots | threads | simulated | wall | real-time factor | physics steps/s | outcome |"
        );
        outln!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |");
    }
    let mut loaded = Vec::new();
    for (name, g, s) in cases {
        let graph = bite_core::graph::load_str(&Arc::from(format!("{name} (built in)")), &g)
            .map_err(bad_input)?;
        let sc = Scenario::load_str(&Arc::from(format!("{name} scenario (built in)")), &s)
            .map_err(bad_input)?;
        let mission = prepare(&graph, &sc, None, &registry()).map_err(bad_input)?;
        loaded.push((name, sc, mission));
    }
    let mut curves = Vec::new();
    for t in b.scaling.thread_counts()? {
        let (pool, threads_used) = (&t.pool, t.count);
        let mut points = Vec::new();
        for (k, (name, sc, mission)) in loaded.iter().enumerate() {
            let mut factors = Vec::new();
            for rep in 0..b.scaling.repeat {
                let bar = ProgressBar::new(sc.time_limit.as_secs().max(1));
                bar.set_style(
                    ProgressStyle::with_template(
                        "{prefix:>16} simulated {pos}/{len} s [{bar:30}] ({elapsed})",
                    )
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                bar.set_prefix(name.clone());
                benchkit::reset_peak_memory();
                let start = std::time::Instant::now();
                let mut on_progress = |p: Progress| bar.set_position(p.now.as_secs_f64() as u64);
                let report = run(
                    mission.clone(),
                    sc,
                    RunOptions {
                        seed: Some(b.seed),
                        progress: Some(&mut on_progress),
                        pool: pool.clone(),
                        ..RunOptions::default()
                    },
                )
                .map_err(bad_input)?;
                let wall = start.elapsed().as_secs_f64();
                let peak = benchkit::peak_memory_kb();
                bar.finish_and_clear();
                let sim = report.end.as_secs_f64();
                let hz = sc.physics.as_ref().map_or(0.0, |p| p.hz);
                let factor = sim / wall.max(1e-9);
                let n = mission.graph().roster().len();
                factors.push(factor);
                let steps = sim * hz / wall.max(1e-9);
                rows.push(serde_json::json!({
                    "run": name, "robots": n, "threads": threads_used, "repeat": rep,
                    "simulated_s": sim, "wall_s": wall,
                    "real_time_factor": factor, "physics_steps_per_s": steps,
                    "peak_rss_kb": peak,
                    "completed": report.summary.completed,
                    "outcome": report.summary.outcome,
                    "timeouts": report.summary.timeouts,
                }));
                if !b.json {
                    outln!(
                        "| {name} | {n} | {threads_used} | {sim:.1} s | {wall:.2} s | {factor:.1}× | {steps:.0} | {} |",
                        report.summary.outcome.label()
                    );
                }
            }
            if k >= first_at_scale {
                points.push((mission.graph().roster().len(), factors));
            }
        }
        curves.push(plot::Curve {
            label: format!("{mission_name} mission, {}", t.label),
            points,
        });
    }
    if b.json {
        outln!("{}", serde_json::json!({ "rows": rows }));
    }
    if let Some(path) = &b.scaling.plot {
        plot::scaling(
            path,
            &format!(
                "bite bench sim: {mission_name} mission, {} s simulated, {} run(s) each",
                b.seconds, b.scaling.repeat
            ),
            &curves,
        )?;
        eprintln!("wrote {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// What `bite bench team` runs.
struct TeamBench<'a> {
    robots: &'a [usize],
    graph: Option<&'a Path>,
    scenario: Option<&'a Path>,
    config: Option<&'a Path>,
    sim_time: Option<Duration>,
    seed: u64,
    scaling: &'a benchkit::Scaling,
    json: bool,
}

#[allow(clippy::disallowed_methods)] // a benchmark measures wall time
fn cmd_bench_team(b: TeamBench<'_>) -> Result<ExitCode> {
    let g = load_graph(b.graph, b.config)?;
    let sc = match (b.graph, b.scenario) {
        (_, Some(s)) => Scenario::load(s).map_err(bad_input)?,
        (None, None) => load_scenario(None, None, &g, true)?,
        (Some(p), None) => load_scenario(Some(p), None, &g, true)?,
    };
    let mut rows = Vec::new();
    let mut curves = Vec::new();
    if !b.json {
        outln!(
            "| robots | threads | simulated | wall | simulated s per wall s | robot-ticks per s | peak memory | messages sent / delivered | outcome |"
        );
        outln!("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |");
    }
    for t in b.scaling.thread_counts()? {
        let (pool, threads_used) = (&t.pool, t.count);
        let mut points = Vec::new();
        for &robots in b.robots {
            let mission = prepare(&g, &sc, Some(robots), &registry()).map_err(bad_input)?;
            eprintln!(
                "bench team: {robots} robots, graph `{}`, scenario `{}`, control at {} Hz, seed {}, {} thread(s)",
                mission.graph().name(),
                sc.name,
                sc.control_hz,
                b.seed,
                threads_used,
            );
            let mut factors = Vec::new();
            for rep in 0..b.scaling.repeat {
                let bar = ProgressBar::new(b.sim_time.unwrap_or(sc.time_limit).as_secs().max(1));
                bar.set_style(
                    ProgressStyle::with_template(
                        "{spinner} simulated {pos}/{len} s [{bar:30}] {msg} ({elapsed})",
                    )
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                benchkit::reset_peak_memory();
                let start = std::time::Instant::now();
                let mut on_progress = |p: Progress| {
                    bar.set_position(p.now.as_secs_f64() as u64);
                    bar.set_message(format!("{}/{} done", p.finished, p.robots));
                };
                let report = run(
                    mission.clone(),
                    &sc,
                    RunOptions {
                        seed: Some(b.seed),
                        time_limit: b.sim_time,
                        log: None,
                        record: false,
                        progress: Some(&mut on_progress),
                        pool: pool.clone(),
                        ..Default::default()
                    },
                )
                .map_err(bad_input)?;
                let wall = start.elapsed().as_secs_f64();
                let peak = benchkit::peak_memory_kb();
                bar.finish_and_clear();
                let sim = report.end.as_secs_f64();
                let s = &report.summary;
                let factor = sim / wall.max(1e-9);
                let ticks = robots as f64 * sim * sc.control_hz / wall.max(1e-9);
                factors.push(factor);
                if !b.json {
                    outln!(
                        "| {robots} | {threads_used} | {sim:.1} s | {wall:.2} s | {factor:.2}× | {ticks:.0} | {} | {} / {} | {} |",
                        peak.map_or("?".to_string(), |kb| format!("{} MB", kb / 1024)),
                        s.messages.total(),
                        s.network.delivered,
                        s.outcome.label(),
                    );
                }
                rows.push(serde_json::json!({
                    "robots": robots, "threads": threads_used, "repeat": rep,
                    "simulated_s": sim, "wall_s": wall,
                    "real_time_factor": factor, "robot_ticks_per_s": ticks,
                    "peak_rss_kb": peak,
                    "completed": s.completed, "outcome": s.outcome, "timeouts": s.timeouts,
                    "messages": s.messages.total(),
                    "delivered": s.network.delivered, "seed": b.seed,
                    "side_by_side": report.batched,
                }));
            }
            points.push((robots, factors));
        }
        curves.push(plot::Curve {
            label: t.label,
            points,
        });
    }
    if b.json {
        outln!("{}", serde_json::json!({ "rows": rows }));
    }
    if let Some(path) = &b.scaling.plot {
        let span = b
            .sim_time
            .map_or("until the mission completes".to_string(), |d| {
                format!("{} s simulated", d.as_secs_f64())
            });
        plot::scaling(
            path,
            &format!(
                "bite bench team: `{}`, {span}, {} run(s) each",
                g.name(),
                b.scaling.repeat
            ),
            &curves,
        )?;
        eprintln!("wrote {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

#[allow(clippy::disallowed_methods)] // a benchmark measures wall time
fn cmd_bench_protocols(sizes: &[usize], large: usize, seed: u64, json: bool) -> Result<ExitCode> {
    use bite_sim::probe::{GRAPH_LIBRARY, LIBRARY, ProbeSpec, probe};
    let reg = registry();
    let all: Vec<_> = LIBRARY.iter().chain(GRAPH_LIBRARY).collect();
    let bar = ProgressBar::new((all.len() * sizes.len()) as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {pos}/{len} [{bar:30}] {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for (kind, protocol, params) in all {
        for &n in sizes {
            bar.set_message(format!("{protocol}, {n} robots"));
            let mut spec = ProbeSpec::library(*kind, protocol, *params, n);
            spec.seed = seed;
            let start = std::time::Instant::now();
            let r = probe(&spec, &reg).map_err(bad_input)?;
            let wall = start.elapsed().as_secs_f64();
            rows.push((protocol, n, r, wall));
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let mut json_rows = Vec::new();
    let mut json_large = Vec::new();
    if !json {
        outln!("One decision per protocol, fault-free, 3 children / successors, 10 ms latency.");
        outln!("| protocol | n | messages | rounds | decided | wall |");
        outln!("| --- | ---: | ---: | ---: | --- | ---: |");
    }
    for (protocol, n, r, wall) in &rows {
        let ok = r.completed && r.violations.is_empty() && r.timeouts == 0;
        json_rows.push(serde_json::json!({
            "protocol": protocol, "robots": n, "messages": r.messages, "rounds": r.rounds,
            "decided": ok, "wall_s": wall,
        }));
        if json {
            continue;
        }
        outln!(
            "| `{protocol}` | {n} | {} | {:.0} | {} | {:.1} ms |",
            r.messages,
            r.rounds,
            if ok { "yes" } else { "NO" },
            wall * 1e3
        );
    }
    if large > 0 && !json {
        outln!("");
        outln!(
            "{large} robots, {large} tasks (one robot each, utilities from positions), one allocation:"
        );
        outln!("| protocol | messages | messages / task | rounds | total utility | wall |");
        outln!("| --- | ---: | ---: | ---: | ---: | ---: |");
    }
    if large > 0 {
        for protocol in ["alloc.auction", "alloc.token", "alloc.optimal"] {
            eprintln!("{protocol}: {large} robots x {large} tasks ...");
            let mut spec = ProbeSpec::new(bite_core::msg::Kind::Allocate, protocol, large);
            spec.items = large;
            spec.one_each = true;
            spec.utilities = true;
            spec.seed = seed;
            spec.deadline = Some(Duration::from_secs(24 * 3600));
            let start = std::time::Instant::now();
            let r = probe(&spec, &reg).map_err(bad_input)?;
            let wall = start.elapsed().as_secs_f64();
            json_large.push(serde_json::json!({
                "protocol": protocol, "robots": large, "tasks": large, "messages": r.messages,
                "rounds": r.rounds, "total_utility": r.utility, "wall_s": wall,
            }));
            if json {
                continue;
            }
            outln!(
                "| `{protocol}` | {} | {:.2} | {:.0} | {:.0} | {:.2} s |",
                r.messages,
                r.messages as f64 / large as f64,
                r.rounds,
                r.utility.unwrap_or(f64::NAN),
                wall
            );
        }
    }
    if json {
        outln!(
            "{}",
            serde_json::json!({ "rows": json_rows, "large": json_large })
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// mimalloc instead of glibc's allocator: the kernels, the simulator and the
/// compiler make many small, short-lived allocations; measured in
/// docs/performance.md, chosen in docs/dependencies.md.
#[global_allocator]
static ALLOC: bite_alloc::MiMalloc = bite_alloc::MiMalloc;

fn main() -> ExitCode {
    let cli = Cli::parse();
    // A command that ends with its work keeps the memory it frees for its
    // next allocations (the services keep mimalloc's default and give it
    // back; bite-alloc's docs say why).
    if !matches!(cli.cmd, Cmd::Studio(_) | Cmd::Robot(_) | Cmd::Sim { .. }) {
        bite_alloc::keep_freed_memory();
    }
    // `BITE_PARSE_ONLY=1`: check the command line and stop (exit 0, or 2
    // on a bad one), so that the README test can check the commands it
    // shows that run for minutes or start a team over Zenoh.
    if std::env::var_os("BITE_PARSE_ONLY").is_some() {
        return ExitCode::SUCCESS;
    }
    let _ = PROTOCOL_FILES.set(cli.protocols.clone());
    if !cli.protocols.is_empty() {
        let mut r = bite_protocols::registry();
        if let Err(d) = bite_protocols::load_protocol_files(&mut r, &cli.protocols) {
            let _ = bad_input(d);
            return ExitCode::from(2);
        }
        let _ = REGISTRY.set(r);
    }
    let result = match cli.cmd {
        Cmd::Run(a) => cmd_run(a),
        Cmd::Check { graph, config } => {
            if config.is_none() && is_protocol_file(&graph) {
                cmd_check_protocol(&graph)
            } else {
                cmd_check(&graph, config.as_deref())
            }
        }
        Cmd::Sweep(a) => sweep::cmd_sweep(a),
        Cmd::Experiment(a) => experiment::cmd_experiment(a),
        Cmd::Tune(a) => tune::cmd_tune(a),
        Cmd::Replay { file } => team::cmd_replay(&file),
        Cmd::Studio(a) => studio::cmd_studio(a),
        Cmd::Log {
            which: LogCmd::Convert { inputs, output },
        } => viz::cmd_convert(&inputs, &output),
        Cmd::Graph {
            graph,
            config,
            output,
            svg,
            ..
        } => cmd_graph(&graph, config.as_deref(), output.as_deref(), svg),
        Cmd::Compile {
            mission,
            dot,
            world,
            library,
            scenario,
            robots,
            origin,
            output,
        } => cmd_compile(CompileArgs {
            mission: &mission,
            dot,
            world,
            library: library.as_deref(),
            scenario: scenario.as_deref(),
            robots,
            origin,
            output: output.as_deref(),
        }),
        Cmd::Protocols => Ok(cmd_protocols()),
        Cmd::Robot(a) => team::cmd_robot(a),
        Cmd::Sim {
            which: SimCmd::Serve(a),
        } => team::cmd_serve(a),
        Cmd::Launch(a) => team::cmd_launch(a),
        Cmd::Submit(a) => team::cmd_submit(a),
        Cmd::Keygen { output } => team::cmd_keygen(output.as_deref()),
        Cmd::Bench {
            which:
                BenchCmd::Team {
                    robots,
                    graph,
                    scenario,
                    config,
                    sim_time,
                    seed,
                    scaling,
                    json,
                },
        } => cmd_bench_team(TeamBench {
            robots: &robots,
            graph: graph.as_deref(),
            scenario: scenario.as_deref(),
            config: config.as_deref(),
            sim_time,
            seed,
            scaling: &scaling,
            json,
        }),
        Cmd::Bench {
            which:
                BenchCmd::Sim {
                    robots,
                    seconds,
                    mission,
                    seed,
                    scaling,
                    json,
                },
        } => cmd_bench_sim(SimBench {
            robots: &robots,
            seconds,
            mission,
            seed,
            scaling: &scaling,
            json,
        }),
        Cmd::Bench {
            which:
                BenchCmd::Zenoh {
                    robots,
                    decisions,
                    pings,
                    out,
                    json,
                    tuning,
                },
        } => zbench::cmd_bench_zenoh(&robots, decisions, pings, &out, json, &tuning),
        Cmd::Bench {
            which: BenchCmd::Pong { team, listen },
        } => zbench::cmd_pong(&team, &listen),
        Cmd::Bench {
            which: BenchCmd::Lap { input, repeat },
        } => lapbench::cmd_bench_lap(&input, repeat),
        Cmd::Bench {
            which:
                BenchCmd::Protocols {
                    robots,
                    large,
                    seed,
                    json,
                },
        } => cmd_bench_protocols(&robots, large, seed, json),
    };
    match result {
        Ok(code) => code,
        Err(e) => match e.downcast_ref::<Reported>() {
            Some(Reported(code)) => ExitCode::from(*code),
            None => {
                eprintln!("error: {e:#}");
                ExitCode::from(3)
            }
        },
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_run_draws_at_most_ten_thousand_frames_its_first_ones() {
        use super::frame_count;
        assert_eq!(frame_count(55.2, 1.0), (56, 56));
        assert_eq!(frame_count(0.0, 1.0), (1, 1));
        assert_eq!(frame_count(200.0, 0.01), (10_000, 20_001));
        assert_eq!(frame_count(1e300, 0.01).0, 10_000);
    }
}
