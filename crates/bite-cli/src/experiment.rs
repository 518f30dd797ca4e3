//! `bite experiment FILE`: protocols compared by configuration only, as
//! the BITE paper's Table II and Figure 3 do, on any mission.
//!
//! An experiment file (YAML, `docs/experiments.md`) names missions,
//! configurations (files or globs), worlds or scenarios, fault classes,
//! seeds and the figures to compare. Every run is a pure function of its
//! case and seed; runs go on every core and are appended, as they finish,
//! to `runs.jsonl` in the output directory, so an interrupted experiment
//! resumes where it stopped (a run whose key is there is not run again).
//! From all runs, in plan order, come `runs.csv`, the plots (SVG and PNG)
//! and `report.md`: the same bytes for any thread count.

use crate::stats::{self, Describe};
use crate::{bad_input, load_team, registry, sibling_scenario};
use anyhow::{Context, Result};
use bite_core::diag::{Diagnostic, Diagnostics, Loc};
use bite_sim::sweep::{Case, Class, RunResult, RunSpec, run_one};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Deserialize;
use serde_json::{Map, Value as Json};
use serde_saphyr::Spanned;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, Write};
use std::path::{Component, Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

/// `bite experiment` arguments.
#[derive(clap::Args)]
pub struct ExperimentArgs {
    /// The experiment file (YAML; `docs/experiments.md`).
    pub file: PathBuf,
    /// Seeds, overriding the file's: `1..30`, `7` or `1,5,9`.
    #[arg(long)]
    pub seeds: Option<String>,
    /// Output directory (default: `out/experiment-<name>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Threads, 1 to 1024 (default: every core). The results are the same for any number.
    #[arg(long, value_parser = crate::parse_jobs)]
    pub jobs: Option<usize>,
    /// Forget the runs already in the output directory and run everything.
    #[arg(long)]
    pub fresh: bool,
}

// ----- The file -----

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ExperimentSpec {
    experiment: String,
    #[serde(default)]
    description: Option<String>,
    #[serde(default)]
    seeds: Option<Spanned<SeedsSpec>>,
    missions: Vec<MissionSpec>,
    #[serde(default)]
    faults: Vec<Spanned<String>>,
    #[serde(default)]
    figures: Vec<Spanned<String>>,
    #[serde(default)]
    compare: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum SeedsSpec {
    One(u64),
    List(Vec<u64>),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MissionSpec {
    graph: Spanned<String>,
    #[serde(default)]
    label: Option<Spanned<String>>,
    #[serde(default)]
    library: Option<Spanned<String>>,
    #[serde(default)]
    configs: Vec<Spanned<ConfigEntry>>,
    #[serde(default)]
    worlds: Vec<Spanned<String>>,
    #[serde(default)]
    scenarios: Vec<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ConfigEntry {
    Path(String),
    Full(ConfigFull),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFull {
    file: String,
    #[serde(default)]
    label: Option<String>,
    #[serde(default)]
    seed_offset: u64,
}

/// One case of the experiment: a mission under a configuration in a
/// scenario, with what names it in tables.
pub struct CaseMeta {
    /// The mission's label (its file stem unless the file gives one).
    pub mission: String,
    /// The configuration's label (its file stem, `default` without one).
    pub config: String,
    /// `timed` or `physics`.
    pub world: String,
    /// The scenario's name.
    pub scenario: String,
    /// Added to every seed of this case (a second series of runs of the
    /// same configuration on other seeds).
    pub seed_offset: u64,
    /// Fingerprint of what the case runs (graph, bindings, scenario, this
    /// program's version): a finished run is reused only for the same one.
    pub fingerprint: u64,
}

/// A loaded experiment: its cases and what to do with them.
pub struct Experiment {
    /// Its name.
    pub name: String,
    /// What it is about.
    pub description: Option<String>,
    /// Runnable cases.
    pub cases: Vec<Case>,
    /// Their names.
    pub meta: Vec<CaseMeta>,
    /// Fault classes.
    pub classes: Vec<Class>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Figures of the report (column names of `runs.csv`).
    pub figures: Vec<String>,
    /// The figure compared pairwise.
    pub compare: String,
}

/// Figures reported when the file names none.
pub const DEFAULT_FIGURES: [&str; 5] = [
    "task_time",
    "interaction_time.sync",
    "interaction_time.allocate",
    "interaction_time.total",
    "messages.total",
];

/// FNV-1a over bytes: a stable fingerprint (the standard hasher is not
/// stable across releases).
pub fn fnv(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// `a/./b/../c` → `a/c`, lexically (so that paths relative to the
/// experiment file read well in tables and replay commands).
fn normalize(p: &Path) -> PathBuf {
    let mut out: Vec<Component<'_>> = Vec::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => match out.last() {
                Some(Component::Normal(_)) => {
                    out.pop();
                }
                _ => out.push(c),
            },
            _ => out.push(c),
        }
    }
    if out.is_empty() {
        PathBuf::from(".")
    } else {
        out.iter().collect()
    }
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

fn error(file: &Arc<str>, at: Loc, code: &'static str, msg: impl Into<String>) -> Diagnostic {
    Diagnostic::error(file, at, code, msg)
}

fn loc<T>(s: &Spanned<T>) -> Loc {
    Loc::from(s.referenced)
}

/// Parse the seeds of `--seeds` or a file.
fn seeds_of(s: &SeedsSpec) -> Result<Vec<u64>, String> {
    match s {
        SeedsSpec::One(n) => Ok(vec![*n]),
        SeedsSpec::List(v) if !v.is_empty() => {
            crate::sweep::no_repeated_seed(v)?;
            Ok(v.clone())
        }
        SeedsSpec::List(_) => Err("an empty list of seeds".to_string()),
        SeedsSpec::Text(t) => crate::sweep::parse_seeds(t),
    }
}

/// Load an experiment file: every mission, configuration and scenario it
/// names, checked before anything runs.
pub fn load(path: &Path, seeds_override: Option<&str>) -> Result<Experiment> {
    let (file, text) = bite_core::yaml::read_file(path).map_err(bad_input)?;
    let spec: ExperimentSpec = bite_core::yaml::parse(&file, &text).map_err(bad_input)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let rel = |s: &str| normalize(&dir.join(s));
    let mut diags = Vec::new();
    let seeds = match (seeds_override, &spec.seeds) {
        (Some(s), _) => crate::sweep::parse_seeds(s).map_err(|e| anyhow::anyhow!("--seeds {e}"))?,
        (None, Some(s)) => match seeds_of(&s.value) {
            Ok(v) => v,
            Err(e) => {
                diags.push(error(&file, loc(s), "bad-seeds", e));
                Vec::new()
            }
        },
        (None, None) => (1..=30).collect(),
    };
    let classes: Vec<Class> = if spec.faults.is_empty() {
        vec![Class::None]
    } else {
        spec.faults
            .iter()
            .filter_map(|f| {
                Class::parse(&f.value).or_else(|| {
                    let names = Class::ALL.map(Class::name);
                    let mut d = error(
                        &file,
                        loc(f),
                        "unknown-fault",
                        format!("unknown fault class `{}`", f.value),
                    );
                    d.hint = Some(
                        bite_core::diag::did_you_mean(&f.value, names)
                            .unwrap_or_else(|| format!("one of {}", names.join(", "))),
                    );
                    diags.push(d);
                    None
                })
            })
            .collect()
    };
    if spec.missions.is_empty() {
        diags.push(error(
            &file,
            Loc::UNKNOWN,
            "no-missions",
            "an experiment names at least one mission under `missions:`",
        ));
    }
    // Every mission, configuration and scenario must exist before anything runs.
    let mut wanted: Vec<Wanted> = Vec::new();
    // What names rows must name one thing: a mission once, each label of
    // a mission or configuration once (rows of two under one label would
    // be merged), each world or scenario of a mission once (its runs
    // would count twice as independent samples).
    // A mission is its graph with its command library (one `.rtcl`
    // compiled with two libraries is two missions).
    let mut missions_seen: Vec<((PathBuf, Option<PathBuf>), Loc)> = Vec::new();
    let mut labels_seen: Vec<(String, Loc)> = Vec::new();
    let largest_seed = seeds.iter().copied().max().unwrap_or(0);
    for (mi, m) in spec.missions.iter().enumerate() {
        let graph = rel(&m.graph.value);
        if !graph.exists() {
            diags.push(error(
                &file,
                loc(&m.graph),
                "missing-file",
                format!("mission `{}` does not exist", graph.display()),
            ));
            continue;
        }
        let canon = |p: &PathBuf| p.canonicalize().unwrap_or_else(|_| p.clone());
        let same_file = (
            canon(&graph),
            m.library.as_ref().map(|l| canon(&rel(&l.value))),
        );
        if let Some((_, first)) = missions_seen.iter().find(|(g, _)| *g == same_file) {
            let mut d = error(
                &file,
                loc(&m.graph),
                "duplicate-mission",
                format!(
                    "mission `{}` is listed twice, with the same library (first at line {})",
                    graph.display(),
                    first.line
                ),
            );
            d.hint = Some("list its configurations, worlds and scenarios under one entry".into());
            diags.push(d);
            continue;
        }
        missions_seen.push((same_file, loc(&m.graph)));
        let (label, at) = match &m.label {
            Some(l) => (l.value.clone(), loc(l)),
            None => (stem(&graph), loc(&m.graph)),
        };
        if let Some((_, first)) = labels_seen.iter().find(|(l, _)| *l == label) {
            let mut d = error(
                &file,
                at,
                "duplicate-label",
                format!(
                    "mission label `{label}` names two missions (first at line {}): their rows would be merged",
                    first.line
                ),
            );
            d.hint = Some("give each mission its own `label:`".into());
            diags.push(d);
        }
        labels_seen.push((label, at));
        let mut configs = Vec::new();
        // Each configuration's label, file and seed offset, and where.
        let mut configs_seen: Vec<(String, Option<PathBuf>, u64, Loc)> = Vec::new();
        for c in &m.configs {
            let (pattern, label, offset) = match &c.value {
                ConfigEntry::Path(p) => (p.clone(), None, 0),
                ConfigEntry::Full(f) => (f.file.clone(), f.label.clone(), f.seed_offset),
            };
            let full = rel(&pattern);
            let found: Vec<PathBuf> = if crate::globwalk::is_pattern(&pattern) {
                // The spec's folder is a place, not a pattern.
                let under =
                    Path::new(&glob::Pattern::escape(&dir.to_string_lossy())).join(&pattern);
                match crate::globwalk::glob_files(&normalize(&under).to_string_lossy()) {
                    Ok(v) => v,
                    Err(e) => {
                        let code = match e {
                            crate::globwalk::GlobError::Pattern(_) => "bad-glob",
                            crate::globwalk::GlobError::TooWide { .. } => "too-wide-glob",
                        };
                        diags.push(error(&file, loc(c), code, format!("`{pattern}`: {e}")));
                        continue;
                    }
                }
            } else {
                vec![full.clone()]
            };
            let found: Vec<PathBuf> = found.into_iter().filter(|p| p.exists()).collect();
            if found.is_empty() {
                diags.push(error(
                    &file,
                    loc(c),
                    "missing-file",
                    format!("no configuration file matches `{}`", full.display()),
                ));
            }
            if largest_seed.checked_add(offset).is_none() {
                diags.push(error(
                    &file,
                    loc(c),
                    "bad-seed-offset",
                    format!(
                        "seed_offset {offset} plus seed {largest_seed} is past the largest seed, {}",
                        u64::MAX
                    ),
                ));
                continue;
            }
            let many = found.len() > 1;
            for p in found {
                let l = match (&label, many) {
                    (Some(l), false) => l.clone(),
                    _ => stem(&p),
                };
                let same_file = p.canonicalize().ok();
                if let Some((_, _, _, first)) = configs_seen
                    .iter()
                    .find(|(_, f, o, _)| same_file.is_some() && *f == same_file && *o == offset)
                {
                    let mut d = error(
                        &file,
                        loc(c),
                        "duplicate-config",
                        format!(
                            "configuration `{}` is listed twice with seed_offset {offset} (first at line {}): the same runs twice",
                            p.display(),
                            first.line
                        ),
                    );
                    d.hint = Some("another `seed_offset` runs it on other seeds".into());
                    diags.push(d);
                } else if let Some((_, _, _, first)) =
                    configs_seen.iter().find(|(seen, ..)| *seen == l)
                {
                    let mut d = error(
                        &file,
                        loc(c),
                        "duplicate-label",
                        format!(
                            "configuration label `{l}` names two configurations of mission `{}` (first at line {}): their rows would be merged",
                            graph.display(),
                            first.line
                        ),
                    );
                    d.hint = Some("give each its own `label:`".into());
                    diags.push(d);
                }
                configs_seen.push((l.clone(), same_file, offset, loc(c)));
                configs.push((Some(p), l, offset));
            }
        }
        if m.configs.is_empty() {
            configs.push((None, "default".to_string(), 0));
        }
        let mut picks = Vec::new();
        // Each scenario file picked, and where (a world picks its own).
        let mut scenarios_seen: Vec<(PathBuf, Loc)> = Vec::new();
        let mut twice = |p: &Path, at: Loc, diags: &mut Vec<Diagnostic>| {
            let same_file = p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
            if let Some((_, first)) = scenarios_seen.iter().find(|(s, _)| *s == same_file) {
                diags.push(error(
                    &file,
                    at,
                    "duplicate-scenario",
                    format!(
                        "scenario `{}` is picked twice for mission `{}` (first at line {}): its runs would count twice",
                        p.display(),
                        graph.display(),
                        first.line
                    ),
                ));
                return true;
            }
            scenarios_seen.push((same_file, at));
            false
        };
        for s in &m.scenarios {
            let p = rel(&s.value);
            if p.exists() {
                if twice(&p, loc(s), &mut diags) {
                    continue;
                }
                picks.push(ScenarioPick::File(p));
            } else {
                diags.push(error(
                    &file,
                    loc(s),
                    "missing-file",
                    format!("scenario `{}` does not exist", p.display()),
                ));
            }
        }
        let is_mission = crate::rtcl::is_mission(&graph);
        let worlds: Vec<(String, Loc)> = if m.worlds.is_empty() && m.scenarios.is_empty() {
            if is_mission {
                vec![("physics".to_string(), loc(&m.graph))]
            } else {
                vec![
                    ("timed".to_string(), loc(&m.graph)),
                    ("physics".to_string(), loc(&m.graph)),
                ]
            }
        } else {
            m.worlds.iter().map(|w| (w.value.clone(), loc(w))).collect()
        };
        let mut worlds_seen: Vec<(String, Loc)> = Vec::new();
        for (w, at) in worlds {
            if let Some((_, first)) = worlds_seen.iter().find(|(seen, _)| *seen == w) {
                diags.push(error(
                    &file,
                    at,
                    "duplicate-world",
                    format!(
                        "world `{w}` is listed twice (first at line {}, column {}): its runs would count twice",
                        first.line, first.col
                    ),
                ));
                continue;
            }
            worlds_seen.push((w.clone(), at));
            let physical = match w.as_str() {
                "timed" => false,
                "physics" => true,
                other => {
                    let mut d = error(
                        &file,
                        at,
                        "unknown-world",
                        format!("unknown world `{other}`"),
                    );
                    d.hint = Some("`timed` or `physics`".to_string());
                    diags.push(d);
                    continue;
                }
            };
            let p = sibling_scenario(&graph, physical);
            if p.exists() {
                if twice(&p, at, &mut diags) {
                    continue;
                }
                picks.push(ScenarioPick::File(p));
            } else if !physical && !is_mission {
                picks.push(ScenarioPick::EmptyTimed);
            } else if m.worlds.is_empty() {
                // The default worlds: a graph without a physical scenario
                // runs in the timed world only.
            } else {
                diags.push(error(
                    &file,
                    at,
                    "missing-file",
                    format!(
                        "world `{w}` needs the scenario {}, which does not exist",
                        p.display()
                    ),
                ));
            }
        }
        let _ = &m.library;
        wanted.push((mi, graph, configs, picks));
    }
    let figures: Vec<String> = if spec.figures.is_empty() {
        DEFAULT_FIGURES.iter().map(|s| s.to_string()).collect()
    } else {
        spec.figures.iter().map(|f| f.value.clone()).collect()
    };
    let known = known_columns();
    for f in spec.figures.iter().chain(spec.compare.iter()) {
        if !known.contains(&f.value) {
            let names: Vec<&str> = known.iter().map(String::as_str).collect();
            let mut d = error(
                &file,
                loc(f),
                "unknown-figure",
                format!("`{}` is not a figure of a run's summary", f.value),
            );
            d.hint = bite_core::diag::did_you_mean(&f.value, names);
            diags.push(d);
        }
    }
    if !diags.is_empty() {
        return Err(bad_input(Diagnostics(diags)));
    }
    let compare = spec
        .compare
        .as_ref()
        .map_or_else(|| "task_time".to_string(), |c| c.value.clone());
    // Load every case (parse errors in graphs, configurations and
    // scenarios are reported by their own loaders).
    let mut cases = Vec::new();
    let mut meta = Vec::new();
    for (mi, graph, configs, picks) in wanted {
        let m = &spec.missions[mi];
        let library = m.library.as_ref().map(|l| rel(&l.value));
        let mission_label = m
            .label
            .as_ref()
            .map_or_else(|| stem(&graph), |l| l.value.clone());
        for (cfg, cfg_label, offset) in &configs {
            for pick in &picks {
                let (scenario_path, timed) = match pick {
                    ScenarioPick::File(p) => (Some(p.as_path()), true),
                    ScenarioPick::EmptyTimed => (None, true),
                };
                let (g, scenario) = load_team(
                    Some(&graph),
                    library.as_deref(),
                    cfg.as_deref(),
                    scenario_path,
                    None,
                    timed,
                )?;
                let mission =
                    bite_sim::prepare(&g, &scenario, None, &registry()).map_err(bad_input)?;
                let world = if scenario.physics.is_some() {
                    "physics"
                } else {
                    "timed"
                };
                let mut args = graph.display().to_string();
                if let Some(l) = &library {
                    args.push_str(&format!(" --library {}", l.display()));
                }
                if let Some(c) = cfg {
                    args.push_str(&format!(" --config {}", c.display()));
                }
                match scenario_path {
                    Some(s) => args.push_str(&format!(" --scenario {}", s.display())),
                    None => args.push_str(" --timed"),
                }
                let fingerprint = fnv(format!(
                    "{}\n{:?}\n{:?}\n{}",
                    env!("CARGO_PKG_VERSION"),
                    g,
                    scenario,
                    cfg.as_ref()
                        .and_then(|c| std::fs::read_to_string(c).ok())
                        .unwrap_or_default()
                )
                .as_bytes());
                meta.push(CaseMeta {
                    mission: mission_label.clone(),
                    config: cfg_label.clone(),
                    world: world.to_string(),
                    scenario: scenario.name.clone(),
                    seed_offset: *offset,
                    fingerprint,
                });
                let changes = crate::scenario_changes(&scenario, &mission)?;
                cases.push(Case {
                    args,
                    mission,
                    changes,
                    scenario,
                });
            }
        }
    }
    Ok(Experiment {
        name: spec.experiment,
        description: spec.description,
        cases,
        meta,
        classes,
        seeds,
        figures,
        compare,
    })
}

/// A mission of the file, resolved: its index, file, configurations
/// (file, label, seed offset) and scenarios.
type Wanted = (usize, PathBuf, Vec<ConfigPick>, Vec<ScenarioPick>);

/// A configuration to run: its file (none: the mission's own bindings),
/// its label, and the offset added to its seeds.
type ConfigPick = (Option<PathBuf>, String, u64);

enum ScenarioPick {
    File(PathBuf),
    EmptyTimed,
}

// ----- Rows -----

/// The columns every row starts with, in order.
const ID_COLUMNS: [&str; 9] = [
    "key",
    "experiment",
    "mission",
    "config",
    "world",
    "scenario",
    "fault",
    "seed",
    "outcome",
];

/// Summary fields left out of the rows (the identity columns say them, or
/// they are per-robot or per-point lists).
const SKIPPED: [&str; 6] = ["graph", "config", "scenario", "seed", "points", "outcome"];

/// Flatten a summary into dotted columns: numbers, booleans and text as
/// they are; `{sync, allocate, terminate}` groups get a `.total`; short
/// number lists an index per item; other lists their length.
pub fn flatten(prefix: &str, v: &Json, out: &mut Map<String, Json>) {
    let key = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        Json::Object(m) => {
            for (k, x) in m {
                if prefix.is_empty() && SKIPPED.contains(&k.as_str()) {
                    continue;
                }
                flatten(&key(k), x, out);
            }
            let kinds = ["sync", "allocate", "terminate"];
            if m.len() == 3 && kinds.iter().all(|k| m.get(*k).is_some_and(Json::is_number)) {
                let total: f64 = kinds
                    .iter()
                    .filter_map(|k| m.get(*k).and_then(Json::as_f64))
                    .sum();
                let all_int = kinds
                    .iter()
                    .all(|k| m.get(*k).is_some_and(|x| x.is_u64() || x.is_i64()));
                out.insert(
                    key("total"),
                    if all_int {
                        Json::from(total as u64)
                    } else {
                        Json::from(total)
                    },
                );
            }
        }
        Json::Array(a) if a.len() <= 3 && a.iter().all(Json::is_number) => {
            for (i, x) in a.iter().enumerate() {
                out.insert(key(&i.to_string()), x.clone());
            }
        }
        Json::Array(a) => {
            out.insert(key("len"), Json::from(a.len()));
        }
        other => {
            if !prefix.is_empty() {
                out.insert(prefix.to_string(), other.clone());
            }
        }
    }
}

/// Add the figures of a run's summary to a row (nothing if it panicked).
pub fn figures_of(r: &RunResult, row: &mut Map<String, Json>) {
    if let Some(v) = r
        .summary
        .as_ref()
        .and_then(|s| serde_json::to_value(s.as_ref()).ok())
    {
        flatten("", &v, row);
    }
}

/// Every figure column a run can have, for checking the file's `figures`.
pub fn known_columns() -> BTreeSet<String> {
    // A physical run of the built-in formation has every kind of figure.
    let mut out = BTreeSet::new();
    for c in [
        "task_time",
        "completed",
        "completed_robots",
        "crashed_robots",
        "timeouts",
        "violations",
        "interaction_time_max_total",
        "world.goal_met_at",
        "world.coverage",
        "world.formation_error.0",
        "world.formation_error.1",
        "world.distance.len",
    ] {
        out.insert(c.to_string());
    }
    for g in [
        "interaction_time",
        "interaction_time_max",
        "decisions",
        "messages",
        "bytes",
    ] {
        for k in ["sync", "allocate", "terminate", "total"] {
            out.insert(format!("{g}.{k}"));
        }
    }
    for k in [
        "attempts",
        "delivered",
        "lost",
        "duplicated",
        "partitioned",
        "out_of_range",
        "held",
    ] {
        out.insert(format!("network.{k}"));
    }
    for k in ["messages", "bytes"] {
        out.insert(format!("heartbeats.{k}"));
        for r in ["obligatory", "helpful", "broadcast"] {
            out.insert(format!("sharing.{k}.{r}"));
        }
    }
    out.insert("sharing.dropped".to_string());
    out.insert("sharing.adopted".to_string());
    out.insert("invariants.violations".to_string());
    out
}

/// One finished run as a row: identity columns, figures, faults, replay.
fn row(exp: &Experiment, spec: &RunSpec, r: &RunResult) -> Map<String, Json> {
    let m = &exp.meta[spec.case];
    let mut row = Map::new();
    row.insert("key".into(), Json::from(key(exp, spec)));
    row.insert("experiment".into(), Json::from(exp.name.clone()));
    row.insert("mission".into(), Json::from(m.mission.clone()));
    row.insert("config".into(), Json::from(m.config.clone()));
    row.insert("world".into(), Json::from(m.world.clone()));
    row.insert("scenario".into(), Json::from(m.scenario.clone()));
    row.insert("fault".into(), Json::from(spec.class.name()));
    row.insert("seed".into(), Json::from(spec.seed));
    let outcome = match (&r.outcome, r.panicked) {
        (_, true) => "panicked".to_string(),
        (Some(o), _) => serde_json::to_value(o)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_else(|| format!("{o:?}")),
        (None, false) => "error".to_string(),
    };
    row.insert("outcome".into(), Json::from(outcome));
    figures_of(r, &mut row);
    row.insert("faults".into(), Json::from(r.faults.join(" ")));
    row.insert(
        "detail".into(),
        r.detail.clone().map(Json::from).unwrap_or(Json::Null),
    );
    row.insert("replay".into(), Json::from(r.replay.clone()));
    row
}

/// The key of a run: what it runs and on which seed.
fn key(exp: &Experiment, spec: &RunSpec) -> String {
    let m = &exp.meta[spec.case];
    format!(
        "{}/{}/{}/{}/{}/{:016x}",
        m.mission,
        m.config,
        m.scenario,
        spec.class.name(),
        spec.seed,
        m.fingerprint
    )
}

/// Every run of the experiment, in plan order.
pub fn plan(exp: &Experiment) -> Vec<RunSpec> {
    let mut out = Vec::new();
    for (case, m) in exp.meta.iter().enumerate() {
        for class in &exp.classes {
            for seed in &exp.seeds {
                out.push(RunSpec {
                    case,
                    class: *class,
                    // `load` refused an offset that takes a seed past
                    // `u64::MAX`.
                    seed: seed.saturating_add(m.seed_offset),
                });
            }
        }
    }
    out
}

fn csv_field(v: &Json) -> String {
    let s = match v {
        Json::Null => String::new(),
        Json::String(s) => s.clone(),
        other => other.to_string(),
    };
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s
    }
}

/// The rows as CSV: the identity columns, then every other column in the
/// order first met.
pub fn to_csv(rows: &[&Map<String, Json>]) -> String {
    let mut columns: Vec<String> = ID_COLUMNS.iter().map(|c| c.to_string()).collect();
    let mut seen: BTreeSet<String> = columns.iter().cloned().collect();
    let tail = ["faults", "detail", "replay"];
    for r in rows {
        for k in r.keys() {
            if !tail.contains(&k.as_str()) && seen.insert(k.clone()) {
                columns.push(k.clone());
            }
        }
    }
    columns.extend(tail.iter().map(|s| s.to_string()));
    let mut out = columns.join(",");
    out.push('\n');
    for r in rows {
        let line: Vec<String> = columns
            .iter()
            .map(|c| r.get(c).map(csv_field).unwrap_or_default())
            .collect();
        out.push_str(&line.join(","));
        out.push('\n');
    }
    out
}

/// Read the runs of an earlier invocation (a torn last line is ignored).
fn read_done(path: &Path) -> BTreeMap<String, Map<String, Json>> {
    let mut done = BTreeMap::new();
    if let Ok(f) = std::fs::File::open(path) {
        for line in std::io::BufReader::new(f).lines().map_while(Result::ok) {
            if let Ok(Json::Object(m)) = serde_json::from_str::<Json>(&line)
                && let Some(k) = m.get("key").and_then(Json::as_str)
            {
                done.insert(k.to_string(), m);
            }
        }
    }
    done
}

/// Run the runs of `todo`, appending each as a JSON line to `log` as it
/// finishes; returns how many broke an invariant or panicked.
pub fn execute(
    exp: &Experiment,
    todo: &[RunSpec],
    jobs: usize,
    log: &Path,
    bar: &ProgressBar,
) -> Result<Vec<Map<String, Json>>> {
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(log)
        .with_context(|| format!("opening {}", log.display()))?;
    let sink = Mutex::new(std::io::BufWriter::new(file));
    run_parallel(&exp.cases, todo, jobs, |spec, r| {
        let row = row(exp, spec, &r);
        if let Ok(mut w) = sink.lock() {
            let _ = serde_json::to_writer(&mut *w, &row);
            let _ = writeln!(w);
            let _ = w.flush();
        }
        bar.inc(1);
        row
    })
}

/// Run `specs` of `cases` on `jobs` threads, each result handed to `each`
/// (on the worker that ran it); results come back in the order of
/// `specs`, whatever the thread count. A panic in a run is caught by
/// `run_one` and counted; the default hook is kept from printing each one
/// over the progress bar meanwhile.
pub fn run_parallel<T: Send>(
    cases: &[Case],
    specs: &[RunSpec],
    jobs: usize,
    each: impl Fn(&RunSpec, RunResult) -> T + Sync,
) -> Result<Vec<T>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.max(1))
        .build()
        .context("starting the worker threads")?;
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let out = pool.install(|| {
        specs
            .par_iter()
            .map(|spec| each(spec, run_one(cases, spec)))
            .collect()
    });
    std::panic::set_hook(hook);
    Ok(out)
}

/// `bite experiment`.
#[allow(clippy::disallowed_methods)] // progress shows wall time
pub fn cmd_experiment(a: ExperimentArgs) -> Result<ExitCode> {
    let exp = load(&a.file, a.seeds.as_deref())?;
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(format!("experiment-{}", exp.name)));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let log = out.join("runs.jsonl");
    if a.fresh {
        let _ = std::fs::remove_file(&log);
    }
    let mut done = read_done(&log);
    let all = plan(&exp);
    let todo: Vec<RunSpec> = all
        .iter()
        .filter(|s| !done.contains_key(&key(&exp, s)))
        .cloned()
        .collect();
    let jobs = a.jobs.unwrap_or_else(crate::default_jobs);
    eprintln!(
        "experiment `{}`: {} runs ({} cases × {} fault classes × {} seeds); {} done before, {} to run on {jobs} threads",
        exp.name,
        all.len(),
        exp.cases.len(),
        exp.classes.len(),
        exp.seeds.len(),
        all.len() - todo.len(),
        todo.len()
    );
    let bar = ProgressBar::new(todo.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {pos}/{len} runs [{bar:30}] {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let new = execute(&exp, &todo, jobs, &log, &bar)?;
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    for r in new {
        if let Some(k) = r.get("key").and_then(Json::as_str) {
            done.insert(k.to_string(), r);
        }
    }
    let rows: Vec<&Map<String, Json>> =
        all.iter().filter_map(|s| done.get(&key(&exp, s))).collect();
    std::fs::write(out.join("runs.csv"), to_csv(&rows))
        .with_context(|| format!("writing {}", out.join("runs.csv").display()))?;
    let groups = groups(&exp, &rows);
    let mut pictures = Vec::new();
    for g in &groups {
        pictures.push(crate::plot::figure3(&out, g)?);
        pictures.push(crate::plot::boxes(&out, g, &exp.compare)?);
    }
    let report = report(&exp, &groups, &a, &pictures);
    std::fs::write(out.join("report.md"), &report)
        .with_context(|| format!("writing {}", out.join("report.md").display()))?;
    outln!("{}", console_table(&exp, &groups));
    let broken = rows
        .iter()
        .filter(|r| {
            r.get("outcome").and_then(Json::as_str) == Some("panicked")
                || r.get("invariants.violations")
                    .and_then(Json::as_u64)
                    .is_some_and(|v| v > 0)
        })
        .count();
    let unfinished = rows
        .iter()
        .filter(|r| {
            matches!(
                r.get("outcome").and_then(Json::as_str),
                Some("stalled" | "not-completed")
            )
        })
        .count();
    outln!(
        "{} runs ({} new, {wall:.1} s on {jobs} threads); {unfinished} did not complete, {broken} broke an invariant or panicked",
        rows.len(),
        todo.len()
    );
    outln!(
        "wrote {}/runs.csv, report.md and {} pictures",
        out.display(),
        pictures.len() * 2
    );
    Ok(if broken > 0 {
        ExitCode::from(bite_sim::summary::EXIT_VIOLATION)
    } else {
        ExitCode::SUCCESS
    })
}

// ----- Groups and statistics -----

/// The runs of one mission in one scenario under one fault class, by
/// configuration: what a Figure-3-style chart compares.
pub struct Group {
    /// `mission · scenario · fault`.
    pub title: String,
    /// File-name form of the title.
    pub slug: String,
    /// The world.
    pub world: String,
    /// Configuration labels, in plan order.
    pub configs: Vec<String>,
    /// Per configuration: the rows, in seed order.
    pub rows: Vec<Vec<Map<String, Json>>>,
}

impl Group {
    /// The values of a figure for configuration `i` (runs without it are
    /// left out).
    pub fn values(&self, i: usize, figure: &str) -> Vec<f64> {
        self.rows[i]
            .iter()
            .filter_map(|r| r.get(figure).and_then(Json::as_f64))
            .collect()
    }
    /// The description of a figure for configuration `i`.
    pub fn describe(&self, i: usize, figure: &str) -> Describe {
        stats::describe(&self.values(i, figure))
    }
    /// How many runs of configuration `i` completed (with or without
    /// deadlines), and how many needed a deadline.
    pub fn completion(&self, i: usize) -> (usize, usize, usize) {
        let rows = &self.rows[i];
        let completed = rows
            .iter()
            .filter(|r| r.get("completed").and_then(Json::as_bool) == Some(true))
            .count();
        let deadline = rows
            .iter()
            .filter(|r| r.get("outcome").and_then(Json::as_str) == Some("completed-with-timeouts"))
            .count();
        (rows.len(), completed, deadline)
    }
}

fn slug(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    out.trim_matches('-').to_string()
}

/// Group rows by (mission, scenario, fault), configurations in plan order.
pub fn groups(exp: &Experiment, rows: &[&Map<String, Json>]) -> Vec<Group> {
    let s = |r: &Map<String, Json>, k: &str| {
        r.get(k)
            .and_then(Json::as_str)
            .unwrap_or_default()
            .to_string()
    };
    let mut order: Vec<(String, String, String)> = Vec::new();
    let mut by: BTreeMap<(String, String, String), Group> = BTreeMap::new();
    let one_fault = exp.classes.len() == 1;
    for r in rows {
        let id = (s(r, "mission"), s(r, "scenario"), s(r, "fault"));
        let g = by.entry(id.clone()).or_insert_with(|| {
            order.push(id.clone());
            // The scenario a mission's file name gives is named by its
            // world; another by its own name.
            let world = s(r, "world");
            let place = if id.1 == id.0 || id.1 == format!("{}-physics", id.0) {
                world.clone()
            } else {
                format!("{} ({world})", id.1)
            };
            let title = if one_fault && id.2 == "none" {
                format!("{} · {place}", id.0)
            } else {
                format!("{} · {place} · {}", id.0, id.2)
            };
            Group {
                slug: slug(&title),
                title,
                world,
                configs: Vec::new(),
                rows: Vec::new(),
            }
        });
        let c = s(r, "config");
        let i = match g.configs.iter().position(|x| *x == c) {
            Some(i) => i,
            None => {
                g.configs.push(c);
                g.rows.push(Vec::new());
                g.configs.len() - 1
            }
        };
        g.rows[i].push((*r).clone());
    }
    order.into_iter().filter_map(|k| by.remove(&k)).collect()
}

fn fmt_ci(d: &Describe) -> String {
    if d.n == 0 {
        "—".to_string()
    } else {
        format!("{:.2} ± {:.2}", d.mean, d.ci95)
    }
}

/// The table printed at the end of a run.
fn console_table(exp: &Experiment, groups: &[Group]) -> String {
    let mut s = String::new();
    for g in groups {
        s.push_str(&format!("\n{}\n", g.title));
        s.push_str(&format!(
            "{:<12} {:>5} {:>10} {:>18} {:>9}",
            "config", "runs", "completed", exp.compare, "median"
        ));
        for f in exp.figures.iter().filter(|f| **f != exp.compare) {
            s.push_str(&format!(" {:>18}", short(f)));
        }
        s.push('\n');
        for (i, c) in g.configs.iter().enumerate() {
            let (n, completed, _) = g.completion(i);
            let d = g.describe(i, &exp.compare);
            s.push_str(&format!(
                "{:<12} {:>5} {:>9.0}% {:>18} {:>9.2}",
                c,
                n,
                100.0 * completed as f64 / n.max(1) as f64,
                fmt_ci(&d),
                d.median
            ));
            for f in exp.figures.iter().filter(|f| **f != exp.compare) {
                s.push_str(&format!(" {:>18}", fmt_ci(&g.describe(i, f))));
            }
            s.push('\n');
        }
    }
    s
}

fn short(f: &str) -> String {
    f.replace("interaction_time", "interaction")
}

/// The Markdown report: per group, the table, the pictures, the spread,
/// whether interaction time predicts task time, and every pairwise
/// comparison of the compared figure.
fn report(exp: &Experiment, groups: &[Group], a: &ExperimentArgs, pictures: &[String]) -> String {
    let mut s = String::new();
    s.push_str(&format!("# Experiment `{}`\n\n", exp.name));
    if let Some(d) = &exp.description {
        s.push_str(&format!("{}\n\n", d.trim()));
    }
    let seeds = match (exp.seeds.first(), exp.seeds.last()) {
        (Some(a), Some(b)) if exp.seeds.len() as u64 == b - a + 1 => format!("{a}..{b}"),
        _ => exp
            .seeds
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(","),
    };
    s.push_str(&format!(
        "Made by `bite experiment {} --seeds {seeds}`: {} cases × {} fault classes × {} seeds. \
         Every run is in `runs.csv` with the command that replays it. Means with their 95 % \
         confidence interval (Student's t); differences with a 95 % bootstrap interval (2,000 \
         resamples) and the two-sided Mann–Whitney p-value. \"Seeds needed\": the fewest seeds per \
         side (the first n) from which on the interval of the difference excludes 0 for good.\n\n",
        a.file.display(),
        exp.cases.len(),
        exp.classes.len(),
        exp.seeds.len(),
    ));
    let mut pics = pictures.iter();
    for g in groups {
        s.push_str(&format!("## {}\n\nWorld: {}.\n\n", g.title, g.world));
        for _ in 0..2 {
            if let Some(p) = pics.next() {
                s.push_str(&format!("![{}]({p}.svg)\n\n", g.title));
            }
        }
        s.push_str(&format!(
            "| config | runs | completed | w/ deadline | {} | median |",
            exp.compare
        ));
        let others: Vec<&String> = exp.figures.iter().filter(|f| **f != exp.compare).collect();
        for f in &others {
            s.push_str(&format!(" {f} |"));
        }
        s.push_str("\n|---|---:|---:|---:|---:|---:|");
        for _ in &others {
            s.push_str("---:|");
        }
        s.push('\n');
        let mut task_means = Vec::new();
        let mut inter_means = Vec::new();
        for (i, c) in g.configs.iter().enumerate() {
            let (n, completed, deadline) = g.completion(i);
            let d = g.describe(i, &exp.compare);
            task_means.push(d.mean);
            inter_means.push(g.describe(i, "interaction_time.total").mean);
            s.push_str(&format!(
                "| {c} | {n} | {:.0} % | {deadline} | {} | {:.2} |",
                100.0 * completed as f64 / n.max(1) as f64,
                fmt_ci(&d),
                d.median
            ));
            for f in &others {
                s.push_str(&format!(" {} |", fmt_ci(&g.describe(i, f))));
            }
            s.push('\n');
        }
        let finite: Vec<f64> = task_means
            .iter()
            .copied()
            .filter(|x| x.is_finite())
            .collect();
        if finite.len() >= 2 {
            let best = finite.iter().copied().fold(f64::INFINITY, f64::min);
            let worst = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let name = |v: f64| {
                task_means
                    .iter()
                    .position(|x| *x == v)
                    .map(|i| g.configs[i].clone())
                    .unwrap_or_default()
            };
            s.push_str(&format!(
                "\nSpread of the mean {}: {:.2} (best `{}` {:.2}, worst `{}` {:.2}).",
                exp.compare,
                worst - best,
                name(best),
                best,
                name(worst),
                worst
            ));
            let rho = stats::spearman(&task_means, &inter_means);
            if rho.is_finite() {
                s.push_str(&format!(
                    " Spearman ρ between the mean {} and the mean interaction time over the {} \
                     configurations: {rho:.2}.",
                    exp.compare,
                    g.configs.len()
                ));
            }
            s.push('\n');
        }
        if g.configs.len() >= 2 {
            let mut pairs = Vec::new();
            for i in 0..g.configs.len() {
                for j in i + 1..g.configs.len() {
                    let (va, vb) = (g.values(i, &exp.compare), g.values(j, &exp.compare));
                    let seed =
                        fnv(format!("{}|{}|{}", g.title, g.configs[i], g.configs[j]).as_bytes());
                    pairs.push((i, j, stats::compare(&va, &vb, seed)));
                }
            }
            let ps: Vec<f64> = pairs.iter().map(|(_, _, c)| c.p).collect();
            let adjusted = stats::holm(&ps);
            s.push_str(&format!(
                "\n| {0} of B − A | Δ mean | 95 % CI | p | p (Holm, {1} pairs) | seeds needed | verdict |\n|---|---:|---|---:|---:|---:|---|\n",
                exp.compare,
                pairs.len()
            ));
            for ((i, j, c), holm) in pairs.iter().zip(&adjusted) {
                let (i, j) = (*i, *j);
                let verdict = match c.seeds_needed {
                    Some(_) if c.diff < 0.0 => format!("`{}` lower", g.configs[j]),
                    Some(_) => format!("`{}` lower", g.configs[i]),
                    None => "no difference shown".to_string(),
                };
                s.push_str(&format!(
                    "| `{}` − `{}` | {:+.2} | [{:+.2}, {:+.2}] | {:.3} | {holm:.3} | {} | {verdict} |\n",
                    g.configs[j],
                    g.configs[i],
                    c.diff,
                    c.ci.0,
                    c.ci.1,
                    c.p,
                    c.seeds_needed
                        .map_or_else(|| "—".to_string(), |n| n.to_string()),
                ));
            }
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_normalized_lexically() {
        assert_eq!(
            normalize(Path::new("examples/experiments/../configs/1.yaml")),
            PathBuf::from("examples/configs/1.yaml")
        );
        assert_eq!(normalize(Path::new("./a/./b")), PathBuf::from("a/b"));
        assert_eq!(normalize(Path::new("../x")), PathBuf::from("../x"));
    }

    #[test]
    fn summaries_flatten_to_dotted_columns_with_totals() {
        let v = serde_json::json!({
            "graph": "g",
            "task_time": 12.5,
            "messages": {"sync": 3, "allocate": 4, "terminate": 0},
            "interaction_time": {"sync": 1.5, "allocate": 0.5, "terminate": 0.0},
            "world": {"formation_error": [0.1, 0.3], "distance": [1.0, 2.0, 3.0, 4.0]},
            "stall": null
        });
        let mut m = Map::new();
        flatten("", &v, &mut m);
        assert_eq!(m.get("graph"), None);
        assert_eq!(m["task_time"], 12.5);
        assert_eq!(m["messages.total"], 7);
        assert_eq!(m["interaction_time.total"], 2.0);
        assert_eq!(m["world.formation_error.1"], 0.3);
        assert_eq!(m["world.distance.len"], 4);
        assert_eq!(m["stall"], Json::Null);
    }

    #[test]
    fn csv_quotes_what_needs_quoting() {
        let mut r = Map::new();
        r.insert("key".into(), Json::from("a"));
        r.insert("replay".into(), Json::from("bite run x --fault 'loss=0.1'"));
        r.insert("detail".into(), Json::from("stalled, at \"B\""));
        let csv = to_csv(&[&r]);
        let lines: Vec<&str> = csv.lines().collect();
        assert!(lines[0].starts_with("key,experiment,mission"));
        assert!(lines[0].ends_with("faults,detail,replay"));
        assert!(lines[1].ends_with(",\"stalled, at \"\"B\"\"\",bite run x --fault 'loss=0.1'"));
    }
}
