//! `bite sweep`: the fault matrix of `../shared/RELIABILITY.md` as a
//! command — graphs × configurations × worlds × fault classes × seeds, the
//! invariant checker on every run, on every core.

use crate::{bad_input, load_team, registry};
use anyhow::{Context, Result};
use bite_sim::sweep::{Case, Class, RunResult, plan, run_one, totals};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The seven Table II configurations, built in (for the built-in graph).
const TABLE2: [(&str, &str); 7] = [
    (
        "examples/configs/1.yaml",
        include_str!("../../../examples/configs/1.yaml"),
    ),
    (
        "examples/configs/2.yaml",
        include_str!("../../../examples/configs/2.yaml"),
    ),
    (
        "examples/configs/3.yaml",
        include_str!("../../../examples/configs/3.yaml"),
    ),
    (
        "examples/configs/4.yaml",
        include_str!("../../../examples/configs/4.yaml"),
    ),
    (
        "examples/configs/5.yaml",
        include_str!("../../../examples/configs/5.yaml"),
    ),
    (
        "examples/configs/6.yaml",
        include_str!("../../../examples/configs/6.yaml"),
    ),
    (
        "examples/configs/7.yaml",
        include_str!("../../../examples/configs/7.yaml"),
    ),
];

#[derive(clap::Args)]
pub struct SweepArgs {
    /// Behavior graphs or `.rtcl` missions (default: the built-in formation
    /// example, under the seven Table II configurations).
    #[arg(long = "graph")]
    graphs: Vec<PathBuf>,
    /// Configuration files (each graph runs under each; default: none, or
    /// Table II for the built-in formation example).
    #[arg(long = "config")]
    configs: Vec<PathBuf>,
    /// The scenario every graph runs against (default: each graph's own,
    /// `scenarios/<stem>-physics.yaml` or `<stem>.yaml` next to it). It
    /// runs in its own world: the `--worlds` that is not its kind is
    /// skipped.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Team size (default: each scenario's, else each graph's), as `bite
    /// run --robots` (1 to 1,000,000): the faults of each class pick
    /// their robots from this team.
    #[arg(long, value_parser = crate::parse_robots)]
    robots: Option<usize>,
    /// Worlds: `timed`, `physics` (a graph without a physical scenario
    /// runs in the timed world only; a mission, `.rtcl`, and a graph with
    /// only a physical scenario beside it, in the physical world only).
    #[arg(long, value_delimiter = ',', default_values_t = ["timed".to_string(), "physics".to_string()])]
    worlds: Vec<String>,
    /// Fault classes (default: all): none, loss, heavy-loss, duplication,
    /// jitter, partition, one-way, hold, pause, crash, leader-crash,
    /// restart, clock-skew, injection.
    #[arg(long, value_delimiter = ',')]
    classes: Vec<String>,
    /// Seeds: `1..30`, `7` or `1,5,9`.
    #[arg(long, default_value = "1..5")]
    seeds: String,
    /// Threads, 1 to 1024 (default: every core). Results are the same for any number.
    #[arg(long, value_parser = crate::parse_jobs)]
    jobs: Option<usize>,
    /// Where to write one JSON line per run.
    #[arg(long, default_value = "out/sweep.jsonl")]
    out: PathBuf,
    /// Print the totals as JSON instead of tables.
    #[arg(long)]
    json: bool,
}

/// Parse `1..30`, `7` or `1,5,9`.
pub fn parse_seeds(s: &str) -> Result<Vec<u64>, String> {
    let bad = || format!("`{s}`: seeds are `FIRST..LAST`, one number, or a comma list");
    if let Some((a, b)) = s.split_once("..") {
        let a: u64 = a.trim().parse().map_err(|_| bad())?;
        let b: u64 = b
            .trim()
            .trim_start_matches('=')
            .parse()
            .map_err(|_| bad())?;
        if b < a || b - a > 1_000_000 {
            return Err(bad());
        }
        return Ok((a..=b).collect());
    }
    let seeds: Vec<u64> = s
        .split(',')
        .map(|x| x.trim().parse::<u64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    no_repeated_seed(&seeds)?;
    Ok(seeds)
}

/// A seed given twice would run the same runs twice and count them as
/// independent samples: refused.
pub fn no_repeated_seed(seeds: &[u64]) -> Result<(), String> {
    let mut seen = std::collections::BTreeSet::new();
    match seeds.iter().find(|s| !seen.insert(**s)) {
        Some(s) => Err(format!(
            "seed {s} is given twice: each seed is one run, counted once"
        )),
        None => Ok(()),
    }
}

fn build_cases(a: &SweepArgs) -> Result<Vec<Case>> {
    let mut cases = Vec::new();
    let graphs: Vec<Option<&Path>> = if a.graphs.is_empty() {
        vec![None]
    } else {
        a.graphs.iter().map(|g| Some(g.as_path())).collect()
    };
    let tmp = std::env::temp_dir().join(format!("bite-sweep-{}", std::process::id()));
    for g in graphs {
        // Configurations: the given files, or Table II for the built-in
        // example (written out so that the loader reports real paths).
        let configs: Vec<(Option<PathBuf>, String)> = if !a.configs.is_empty() {
            a.configs
                .iter()
                .map(|c| (Some(c.clone()), format!(" --config {}", c.display())))
                .collect()
        } else if g.is_none() {
            std::fs::create_dir_all(&tmp)
                .context("a temporary directory for the configurations")?;
            let mut v = Vec::new();
            for (name, text) in TABLE2 {
                let p = tmp.join(name.replace('/', "_"));
                std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
                v.push((Some(p), format!(" --config {name}")));
            }
            v
        } else {
            vec![(None, String::new())]
        };
        let physics_too = a.worlds.iter().any(|w| w == "physics");
        for (cfg, cfg_args) in configs {
            for w in &a.worlds {
                let timed = match w.as_str() {
                    "timed" => true,
                    "physics" => false,
                    other => anyhow::bail!("unknown world `{other}`: timed or physics"),
                };
                // A graph that has only a physical scenario beside it (the
                // box push, a coverage) would run in an empty timed world
                // where nothing it waits for ever happens: every run a
                // stall that says nothing about the team. Its timed world
                // is skipped (the physical one runs it).
                if let Some(p) = g.filter(|_| timed && physics_too && a.scenario.is_none())
                    && !crate::sibling_scenario(p, false).exists()
                    && crate::sibling_scenario(p, true).exists()
                {
                    eprintln!(
                        "note: {} has a physical scenario only: the timed world is skipped",
                        p.display()
                    );
                    continue;
                }
                let (graph, scenario) = load_team(
                    g,
                    None,
                    cfg.as_deref(),
                    a.scenario.as_deref(),
                    a.robots,
                    timed,
                )?;
                if !timed && scenario.physics.is_none() {
                    continue;
                }
                // A physical scenario runs in its own world only: a given
                // one, or the one a mission (`.rtcl`) always runs in (its
                // "timed" runs would be the physical ones again).
                if timed && scenario.physics.is_some() {
                    continue;
                }
                let mission = bite_sim::prepare(&graph, &scenario, a.robots, &registry())
                    .map_err(bad_input)?;
                let mut args = g.map(|p| p.display().to_string()).unwrap_or_default();
                args.push_str(&cfg_args);
                if let Some(sc) = &a.scenario {
                    args.push_str(&format!(" --scenario {}", sc.display()));
                }
                if timed {
                    args.push_str(" --timed");
                }
                if let Some(n) = a.robots {
                    args.push_str(&format!(" --robots {n}"));
                }
                let changes = crate::scenario_changes(&scenario, &mission)?;
                cases.push(Case {
                    args: args.trim().to_string(),
                    mission,
                    changes,
                    scenario,
                });
            }
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(cases)
}

/// `bite sweep`.
#[allow(clippy::disallowed_methods)] // the sweep reports its throughput (wall time)
pub fn cmd_sweep(a: SweepArgs) -> Result<ExitCode> {
    let seeds = parse_seeds(&a.seeds).map_err(|e| anyhow::anyhow!(e))?;
    let classes: Vec<Class> = if a.classes.is_empty() {
        Class::ALL.to_vec()
    } else {
        a.classes
            .iter()
            .map(|c| {
                Class::parse(c).ok_or_else(|| {
                    anyhow::anyhow!(
                        "unknown fault class `{c}`: one of {}",
                        Class::ALL.map(Class::name).join(", ")
                    )
                })
            })
            .collect::<Result<_>>()?
    };
    {
        let mut inputs: Vec<(&str, &Path)> =
            a.graphs.iter().map(|g| ("--graph", g.as_path())).collect();
        inputs.extend(a.configs.iter().map(|c| ("--config", c.as_path())));
        inputs.extend(a.scenario.as_deref().map(|s| ("--scenario", s)));
        crate::outputs::check(&inputs, &[("--out", a.out.as_path())])?;
    }
    let cases = build_cases(&a)?;
    if cases.is_empty() {
        anyhow::bail!(
            "nothing to run: no graph has a scenario of the worlds asked for ({}); \
             a mission (`.rtcl`) and a physical scenario run in the `physics` world",
            a.worlds.join(", ")
        );
    }
    let runs = plan(cases.len(), &classes, &seeds);
    let jobs = a.jobs.unwrap_or_else(crate::default_jobs);
    eprintln!(
        "sweep: {} runs ({} missions × {} classes × {} seeds) on {jobs} threads",
        runs.len(),
        cases.len(),
        classes.len(),
        seeds.len()
    );
    let bar = ProgressBar::new(runs.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {pos}/{len} runs [{bar:30}] {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    // A panic in a run is caught and counted; keep the default hook from
    // printing each one over the progress bar.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .context("starting the worker threads")?;
    let results: Vec<RunResult> = pool.install(|| {
        runs.par_iter()
            .map(|spec| {
                let r = run_one(&cases, spec);
                bar.inc(1);
                r
            })
            .collect()
    });
    std::panic::set_hook(hook);
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(&a.out).with_context(|| format!("creating {}", a.out.display()))?,
    );
    for r in &results {
        serde_json::to_writer(&mut f, r)?;
        writeln!(f)?;
    }
    f.flush()?;
    let t = totals(&classes, &results);
    let violations: usize = t.iter().map(|c| c.violations).sum();
    let panics: usize = t.iter().map(|c| c.panics).sum();
    // Robots that sent far faster than any protocol needs (see
    // `bite_sim::chatter`): failures, though no invariant broke.
    let chatter = results.iter().filter(|r| r.chatter).count();
    if a.json {
        let failures: Vec<&RunResult> = results.iter().filter(|r| r.failed()).collect();
        outln!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "runs": results.len(),
                "violations": violations,
                "panics": panics,
                "chatter": chatter,
                "wall_seconds": wall,
                "runs_per_second": results.len() as f64 / wall.max(1e-9),
                "threads": jobs,
                "classes": t,
                "failures": failures,
                "log": a.out.display().to_string(),
            }))?
        );
    } else {
        print_report(&t, &results, wall, jobs, &a.out);
    }
    Ok(if violations > 0 || panics > 0 || chatter > 0 {
        ExitCode::from(bite_sim::summary::EXIT_VIOLATION)
    } else {
        ExitCode::SUCCESS
    })
}

fn print_report(
    t: &[bite_sim::sweep::ClassTotals],
    results: &[RunResult],
    wall: f64,
    jobs: usize,
    out: &Path,
) {
    outln!(
        "{:<13} {:>6} {:>10} {:>13} {:>8} {:>14} {:>11} {:>7} {:>9}",
        "class",
        "runs",
        "completed",
        "w/ timeouts",
        "stalled",
        "not completed",
        "violations",
        "panics",
        "complete"
    );
    for c in t {
        outln!(
            "{:<13} {:>6} {:>10} {:>13} {:>8} {:>14} {:>11} {:>7} {:>8.1}%",
            c.class,
            c.runs,
            c.completed,
            c.completed_with_timeouts,
            c.stalled,
            c.not_completed,
            c.violations,
            c.panics,
            c.completion() * 100.0
        );
    }
    let n = results.len();
    let violations: usize = t.iter().map(|c| c.violations).sum();
    let panics: usize = t.iter().map(|c| c.panics).sum();
    let chatter = match results.iter().filter(|r| r.chatter).count() {
        0 => String::new(),
        c => format!(", {c} with robots chattering"),
    };
    outln!(
        "{n} runs in {wall:.1} s on {jobs} threads ({:.1} runs/s): {violations} with violations{chatter}, {panics} panics; one JSON line per run in {}",
        n as f64 / wall.max(1e-9),
        out.display()
    );
    let failed: Vec<&RunResult> = results.iter().filter(|r| r.failed()).collect();
    if !failed.is_empty() {
        outln!("\nruns that broke an invariant, chattered or panicked (replay each):");
        for r in failed {
            outln!("  {}\n    {}", r.replay, r.detail.as_deref().unwrap_or(""));
        }
    }
    let unfinished: Vec<&RunResult> = results
        .iter()
        .filter(|r| {
            !r.failed()
                && matches!(
                    r.outcome,
                    Some(
                        bite_sim::summary::Outcome::Stalled
                            | bite_sim::summary::Outcome::NotCompleted
                    )
                )
        })
        .collect();
    if !unfinished.is_empty() {
        outln!(
            "\nruns that did not complete ({}; the first 20, every one in the log):",
            unfinished.len()
        );
        for r in unfinished.iter().take(20) {
            outln!(
                "  [{}] {}{}",
                r.class.name(),
                r.replay,
                r.detail
                    .as_deref()
                    .map(|d| format!("\n    {d}"))
                    .unwrap_or_default()
            );
        }
    }
}
