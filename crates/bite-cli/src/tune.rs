//! `bite tune MISSION`: search the protocol bindings of a mission's
//! points for the configuration that does best on an objective.
//!
//! The objective of a run is noisy (skill durations, network delays and
//! protocol randomness all come from the seed), so configurations are
//! compared by **racing** (successive halving over seeds): every candidate
//! runs on a few seeds, the better half goes on to twice as many, and so
//! on until one is left, which has run on every search seed. The search:
//!
//! 1. a race between the mission's own bindings and the shipped
//!    configurations (`--baseline`) picks the starting point;
//! 2. coordinate passes: for each point in turn, a race between the
//!    current best and every compatible protocol (and parameter setting)
//!    at that point, the others kept; the winner is kept.
//!
//! A candidate whose share of completed runs falls below `--min-success`
//! is out of the race. The best configuration is then run on held-out
//! seeds it never saw, next to the baselines, and reported.

use crate::experiment::{self, fnv};
use crate::stats;
use crate::{bad_input, load_team, registry};
use anyhow::{Context, Result};
use bite_core::Config;
use bite_core::graph::BehaviorGraph;
use bite_core::msg::Kind;
use bite_sim::Scenario;
use bite_sim::sweep::{Case, Class, RunSpec};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{Map, Value as Json};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

/// `bite tune` arguments.
#[derive(clap::Args)]
pub struct TuneArgs {
    /// The mission: a behavior graph (YAML) or a `.rtcl` mission.
    pub mission: PathBuf,
    /// The command library for `.rtcl` missions.
    #[arg(long)]
    pub library: Option<PathBuf>,
    /// The scenario (default: as `bite run` picks it).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// The timed-skill world (as `bite run --timed`).
    #[arg(long)]
    pub timed: bool,
    /// Seeds of the search: `1..10`, `7` or `1,5,9`.
    #[arg(long, default_value = "1..10")]
    pub seeds: String,
    /// Held-out seeds the search never sees, for the final comparison.
    #[arg(long, default_value = "101..120")]
    pub holdout: String,
    /// What to minimise: a summary figure (`task_time`, `messages.total`,
    /// `interaction_time.total`; short forms `messages`, `interaction`), or
    /// a weighted sum `task_time=1,messages.total=0.05`.
    #[arg(long, default_value = "task_time")]
    pub objective: String,
    /// The smallest share of completed runs a configuration may have (0–1).
    #[arg(long, default_value_t = 1.0)]
    pub min_success: f64,
    /// Configurations to start from and compare with (files or globs;
    /// default: `configs/*.yaml` next to the mission, those that fit it).
    #[arg(long = "baseline")]
    pub baselines: Vec<String>,
    /// Passes over the points (at least 1).
    #[arg(long, default_value_t = 1, value_parser = parse_passes)]
    pub passes: u64,
    /// Points to leave as they are (names as `bite check` prints them).
    #[arg(long = "keep")]
    pub keep: Vec<String>,
    /// Output directory (default: `out/tune-<mission>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Threads, 1 to 1024 (default: every core). The result is the same for any number.
    #[arg(long, value_parser = crate::parse_jobs)]
    pub jobs: Option<usize>,
}

/// `--passes`: at least one (none would search nothing and still report a
/// pass).
fn parse_passes(s: &str) -> Result<u64, String> {
    match s.parse::<u64>() {
        Ok(0) => Err("at least one pass".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("expected a number of passes, found `{s}`")),
    }
}

/// A weighted sum of summary figures.
#[derive(Clone, Debug, PartialEq)]
pub struct Objective(pub Vec<(String, f64)>);

impl Objective {
    /// Parse `task_time`, `messages`, or `a=1,b=0.5`.
    pub fn parse(s: &str) -> Result<Objective, String> {
        let alias = |n: &str| match n {
            "messages" => "messages.total".to_string(),
            "interaction" | "interaction_time" => "interaction_time.total".to_string(),
            "bytes" => "bytes.total".to_string(),
            other => other.to_string(),
        };
        let known = experiment::known_columns();
        let mut terms = Vec::new();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (name, w) = match part.split_once('=') {
                Some((n, w)) => (
                    n.trim(),
                    w.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|w| w.is_finite())
                        .ok_or_else(|| format!("`{part}`: the weight is not a number"))?,
                ),
                None => (part, 1.0),
            };
            let name = alias(name);
            if !known.contains(&name) {
                let hint = bite_core::diag::did_you_mean(&name, known.iter().map(String::as_str))
                    .map(|h| format!(" ({h})"))
                    .unwrap_or_default();
                return Err(format!("`{name}` is not a figure of a run's summary{hint}"));
            }
            terms.push((name, w));
        }
        if terms.is_empty() {
            return Err("an empty objective".to_string());
        }
        Ok(Objective(terms))
    }
    /// Its value for a row (`None` if a figure is missing).
    pub fn of(&self, row: &Map<String, Json>) -> Option<f64> {
        self.0
            .iter()
            .map(|(n, w)| row.get(n).and_then(Json::as_f64).map(|v| v * w))
            .sum()
    }
}

impl std::fmt::Display for Objective {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = self
            .0
            .iter()
            .map(|(n, w)| {
                if *w == 1.0 {
                    n.clone()
                } else {
                    format!("{w} × {n}")
                }
            })
            .collect();
        write!(f, "{}", parts.join(" + "))
    }
}

/// The binding of each point of a candidate, as the YAML a configuration
/// file writes (`sync.vote`, `{ protocol: ..., params: ... }`).
type Bindings = Vec<String>;

/// One configuration under test.
struct Candidate {
    label: String,
    bindings: Bindings,
    case: Case,
}

/// The search's state: the mission, its points, the candidates, and every
/// run so far (cached by candidate and seed).
struct Search<'a> {
    args: &'a TuneArgs,
    base: BehaviorGraph,
    scenario: Scenario,
    points: Vec<String>,
    objective: Objective,
    candidates: Vec<Candidate>,
    by_bindings: BTreeMap<Bindings, usize>,
    results: BTreeMap<(usize, u64), Map<String, Json>>,
    jobs: usize,
    runs: usize,
    bar: ProgressBar,
    trace: Vec<String>,
}

fn binding_yaml(protocol: &str, params: &Json) -> String {
    if params.is_null() || params.as_object().is_some_and(Map::is_empty) {
        protocol.to_string()
    } else {
        format!("{{ protocol: {protocol}, params: {} }}", flow(params))
    }
}

/// A JSON value as YAML flow style: plain words unquoted.
fn flow(v: &Json) -> String {
    match v {
        Json::Object(m) => {
            let items: Vec<String> = m
                .iter()
                .map(|(k, x)| format!("{}: {}", word(k), flow(x)))
                .collect();
            format!("{{ {} }}", items.join(", "))
        }
        Json::Array(a) => {
            let items: Vec<String> = a.iter().map(flow).collect();
            format!("[{}]", items.join(", "))
        }
        Json::String(s) => word(s),
        other => other.to_string(),
    }
}

/// A string as a YAML scalar: plain when it is a simple word that YAML
/// would not read as something else, quoted otherwise.
fn word(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c))
        && s.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
        && !["true", "false", "null", "yes", "no", "on", "off"].contains(&s);
    if plain {
        s.to_string()
    } else {
        serde_json::to_string(s).unwrap_or_default()
    }
}

fn config_text(name: &str, description: &str, points: &[String], b: &Bindings) -> String {
    let mut s = format!(
        "config: {name}\ndescription: {}\nbindings:\n",
        serde_json::to_string(description).unwrap_or_default()
    );
    for (p, b) in points.iter().zip(b) {
        s.push_str(&format!("  {p}: {b}\n"));
    }
    s
}

impl Search<'_> {
    /// Add a candidate (or find it); `None` when the bindings do not fit
    /// the mission.
    fn candidate(&mut self, label: &str, bindings: Bindings) -> Option<usize> {
        if let Some(i) = self.by_bindings.get(&bindings) {
            return Some(*i);
        }
        let text = config_text("candidate", label, &self.points, &bindings);
        let file: Arc<str> = Arc::from(format!("{label} (candidate)"));
        let cfg = Config::load_str(&file, &text).ok()?;
        let graph = self.base.clone().with_config(&cfg).ok()?;
        let mission = bite_sim::prepare(&graph, &self.scenario, None, &registry()).ok()?;
        let i = self.candidates.len();
        let changes = crate::scenario_changes(&self.scenario, &mission).ok()?;
        self.candidates.push(Candidate {
            label: label.to_string(),
            bindings: bindings.clone(),
            case: Case {
                args: String::new(),
                mission,
                changes,
                scenario: self.scenario.clone(),
            },
        });
        self.by_bindings.insert(bindings, i);
        Some(i)
    }

    /// Run whatever of `cands` × `seeds` has not run yet, on every core.
    fn evaluate(&mut self, cands: &[usize], seeds: &[u64]) -> Result<()> {
        let todo: Vec<(usize, u64)> = cands
            .iter()
            .flat_map(|c| seeds.iter().map(move |s| (*c, *s)))
            .filter(|k| !self.results.contains_key(k))
            .collect();
        if todo.is_empty() {
            return Ok(());
        }
        self.bar.inc_length(todo.len() as u64);
        let cases: Vec<Case> = self.candidates.iter().map(|c| c.case.clone()).collect();
        let specs: Vec<RunSpec> = todo
            .iter()
            .map(|(c, seed)| RunSpec {
                case: *c,
                class: Class::None,
                seed: *seed,
            })
            .collect();
        let bar = &self.bar;
        let rows = experiment::run_parallel(&cases, &specs, self.jobs, |spec, r| {
            let mut row = Map::new();
            let completed = r.summary.as_ref().is_some_and(|s| s.completed) && !r.failed();
            experiment::figures_of(&r, &mut row);
            // `flatten` writes the summary's own `completed`; a run that
            // broke an invariant never counts as completed.
            row.insert("completed".into(), Json::from(completed));
            bar.inc(1);
            ((spec.case, spec.seed), row)
        })?;
        self.runs += rows.len();
        self.results.extend(rows);
        Ok(())
    }

    /// Mean objective and success share of a candidate on `seeds` (the
    /// objective is infinite when the success share is below the bar).
    fn score(&self, c: usize, seeds: &[u64]) -> (f64, f64) {
        let rows: Vec<&Map<String, Json>> = seeds
            .iter()
            .filter_map(|s| self.results.get(&(c, *s)))
            .collect();
        let ok = rows
            .iter()
            .filter(|r| r.get("completed").and_then(Json::as_bool) == Some(true))
            .count();
        let success = ok as f64 / rows.len().max(1) as f64;
        let values: Vec<f64> = rows.iter().filter_map(|r| self.objective.of(r)).collect();
        let mean = if values.is_empty() {
            f64::INFINITY
        } else {
            values.iter().sum::<f64>() / values.len() as f64
        };
        if success + 1e-9 < self.args.min_success {
            (f64::INFINITY, success)
        } else {
            (mean, success)
        }
    }

    /// Successive halving: the winner among `cands` (the first wins ties,
    /// so put the incumbent first).
    fn race(&mut self, what: &str, cands: &[usize], seeds: &[u64]) -> Result<usize> {
        let mut alive: Vec<usize> = cands.to_vec();
        let rounds = (alive.len().max(1) as f64).log2().ceil() as u32;
        for r in 0..=rounds {
            let k = (seeds.len() >> (rounds - r)).max(seeds.len().min(2));
            let s = &seeds[..k.min(seeds.len())];
            self.evaluate(&alive, s)?;
            let mut scored: Vec<(f64, usize, usize)> = alive
                .iter()
                .enumerate()
                .map(|(order, c)| (self.score(*c, s).0, order, *c))
                .collect();
            scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            if r == rounds || alive.len() == 1 {
                alive = scored.iter().map(|x| x.2).collect();
                break;
            }
            let keep = alive.len().div_ceil(2);
            alive = scored.iter().take(keep).map(|x| x.2).collect();
            // Keep the order of entry among survivors (incumbent first).
            alive.sort_by_key(|c| cands.iter().position(|x| x == c));
        }
        let winner = alive.first().copied().unwrap_or(cands[0]);
        let (score, success) = self.score(winner, seeds);
        self.trace.push(format!(
            "{what}: {} candidates → `{}` ({} = {}, {:.0} % completed, {} seeds)",
            cands.len(),
            self.candidates[winner].label,
            self.objective,
            if score.is_finite() {
                format!("{score:.3}")
            } else {
                "—".to_string()
            },
            success * 100.0,
            seeds.len()
        ));
        Ok(winner)
    }
}

/// Every binding a point of `kind` can take: each protocol of that kind
/// with no parameters, and the parameter settings worth trying for those
/// that have them.
fn options(kind: Kind, scenario: &Scenario, graph: &BehaviorGraph) -> Vec<String> {
    let reg = registry();
    let mut names: Vec<&'static str> = reg
        .iter()
        .filter(|p| p.kind() == kind)
        .map(|p| p.name())
        .collect();
    names.sort_unstable();
    let mut out = Vec::new();
    for n in names {
        match n {
            "sync.leader" => {
                for c in ["round-robin", "first", "preferred", "random"] {
                    out.push(binding_yaml(n, &serde_json::json!({ "choose": c })));
                }
            }
            "alloc.by-value" => {
                for v in &scenario.sensed {
                    for o in ["ascending", "descending"] {
                        out.push(binding_yaml(
                            n,
                            &serde_json::json!({ "value": v, "order": o }),
                        ));
                    }
                }
            }
            "alloc.by-attribute" => {
                let mut attrs: Vec<String> = graph
                    .roster()
                    .iter()
                    .flat_map(|(_, r)| r.attributes.keys().cloned())
                    .collect();
                attrs.sort();
                attrs.dedup();
                for a in attrs {
                    out.push(binding_yaml(n, &serde_json::json!({ "attribute": a })));
                }
            }
            other => out.push(other.to_string()),
        }
    }
    out
}

/// A configuration file to compare with, and the `--baseline` pattern
/// that matched it (`None`: named plainly, or found next to the mission).
struct Baseline {
    path: PathBuf,
    pattern: Option<String>,
}

/// The configuration files to compare with.
fn baselines(a: &TuneArgs) -> Result<Vec<Baseline>> {
    if a.baselines.is_empty() {
        // The configurations next to the mission (some of them for other
        // missions: those that do not fit this one are skipped).
        let dir = a.mission.parent().unwrap_or(Path::new(""));
        let pattern = Path::new(&glob::Pattern::escape(&dir.to_string_lossy()))
            .join("configs")
            .join("*.yaml");
        let v = crate::globwalk::glob_files(&pattern.to_string_lossy())
            .map_err(|e| anyhow::anyhow!("{}: {e}", pattern.display()))?;
        return Ok(v
            .into_iter()
            .map(|path| Baseline {
                path,
                pattern: None,
            })
            .collect());
    }
    let mut out = Vec::new();
    for p in &a.baselines {
        // A plain path is the file itself, there or not (its loading says
        // which); a pattern must match a file.
        if !crate::globwalk::is_pattern(p) {
            out.push(Baseline {
                path: PathBuf::from(p),
                pattern: None,
            });
            continue;
        }
        match crate::globwalk::glob_files(p) {
            Ok(v) => {
                if v.is_empty() {
                    anyhow::bail!("--baseline {p}: no file matches");
                }
                out.extend(v.into_iter().map(|path| Baseline {
                    path,
                    pattern: Some(p.clone()),
                }));
            }
            Err(e @ crate::globwalk::GlobError::TooWide { .. }) => {
                anyhow::bail!("--baseline {p}: {e}")
            }
            Err(crate::globwalk::GlobError::Pattern(_)) => out.push(Baseline {
                path: PathBuf::from(p),
                pattern: None,
            }),
        }
    }
    Ok(out)
}

/// `bite tune`.
#[allow(clippy::disallowed_methods)] // reports its wall time
pub fn cmd_tune(a: TuneArgs) -> Result<ExitCode> {
    let seeds = crate::sweep::parse_seeds(&a.seeds).map_err(|e| anyhow::anyhow!("--seeds {e}"))?;
    let holdout =
        crate::sweep::parse_seeds(&a.holdout).map_err(|e| anyhow::anyhow!("--holdout {e}"))?;
    if let Some(s) = seeds.iter().find(|s| holdout.contains(s)) {
        anyhow::bail!(
            "seed {s} is both a search seed and a held-out seed: held-out seeds must be new"
        );
    }
    if !(0.0..=1.0).contains(&a.min_success) {
        anyhow::bail!("--min-success is a share between 0 and 1");
    }
    let objective =
        Objective::parse(&a.objective).map_err(|e| anyhow::anyhow!("--objective {e}"))?;
    let (base, scenario) = load_team(
        Some(&a.mission),
        a.library.as_deref(),
        None,
        a.scenario.as_deref(),
        None,
        a.timed,
    )?;
    let mission0 = bite_sim::prepare(&base, &scenario, None, &registry()).map_err(bad_input)?;
    let bound = mission0.points();
    let points: Vec<String> = bound.iter().map(|(p, _)| p.name.clone()).collect();
    for k in &a.keep {
        if !points.contains(k) {
            anyhow::bail!(
                "--keep {k}: not a point of the mission (the points: {})",
                points.join(", ")
            );
        }
    }
    let own: Bindings = bound
        .iter()
        .map(|(_, b)| binding_yaml(b.protocol.name(), &b.params))
        .collect();
    let kinds: Vec<Kind> = bound.iter().map(|(p, _)| p.kind).collect();
    drop(bound);
    let name = a.mission.file_stem().map_or_else(
        || "mission".to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(format!("tune-{name}")));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let jobs = a.jobs.unwrap_or_else(crate::default_jobs);
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {pos}/{len} runs [{bar:30}] {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut search = Search {
        args: &a,
        base,
        scenario,
        points: points.clone(),
        objective,
        candidates: Vec::new(),
        by_bindings: BTreeMap::new(),
        results: BTreeMap::new(),
        jobs,
        runs: 0,
        bar,
        trace: Vec::new(),
    };
    let started = std::time::Instant::now();
    // The baselines: the mission's own bindings, and the shipped
    // configurations that fit it.
    let mut base_cands: Vec<(String, usize)> = Vec::new();
    if let Some(i) = search.candidate("own bindings", own.clone()) {
        base_cands.push(("own bindings".to_string(), i));
    }
    // A baseline named with `--baseline` must load and fit the mission:
    // one that does not is an error, not a baseline silently left out. Of
    // the files a pattern matches, those that do not fit are skipped, each
    // said, and a pattern none of whose files fits is an error.
    let given = !a.baselines.is_empty();
    let refuse = |p: &Path, d: bite_core::diag::Diagnostics| {
        eprintln!(
            "error: --baseline {}: not a configuration of mission {}",
            p.display(),
            a.mission.display()
        );
        bad_input(d)
    };
    let mut fitting: std::collections::BTreeMap<String, bool> = Default::default();
    for Baseline { path: p, pattern } in baselines(&a)? {
        if let Some(pat) = &pattern {
            fitting.entry(pat.clone()).or_insert(false);
        }
        let m = match Config::load(&p)
            .and_then(|cfg| search.base.clone().with_config(&cfg))
            .and_then(|g| bite_sim::prepare(&g, &search.scenario, None, &registry()))
        {
            Ok(m) => m,
            Err(_) if pattern.is_some() => {
                eprintln!(
                    "note: --baseline {}: {} skipped: not a configuration of mission {}",
                    pattern.as_deref().unwrap_or_default(),
                    p.display(),
                    a.mission.display()
                );
                continue;
            }
            Err(d) if given => return Err(refuse(&p, d)),
            Err(_) => continue,
        };
        if let Some(pat) = pattern {
            fitting.insert(pat, true);
        }
        let b: Bindings = m
            .points()
            .iter()
            .map(|(_, b)| binding_yaml(b.protocol.name(), &b.params))
            .collect();
        let label = p.display().to_string();
        if let Some(i) = search.candidate(&label, b) {
            match base_cands.iter_mut().find(|(_, j)| *j == i) {
                // The same bindings as an earlier baseline: one candidate,
                // both names.
                Some((l, _)) => l.push_str(&format!(" = {label}")),
                None => base_cands.push((label, i)),
            }
        }
    }
    if let Some((pat, _)) = fitting.iter().find(|(_, fits)| !**fits) {
        anyhow::bail!(
            "--baseline {pat}: no file it matches is a configuration of mission {}",
            a.mission.display()
        );
    }
    eprintln!(
        "tune {}: {} points, {} baselines, objective {} (at least {:.0} % completed), {} search seeds, {} held out, {jobs} threads",
        a.mission.display(),
        points.len(),
        base_cands.len(),
        search.objective,
        a.min_success * 100.0,
        seeds.len(),
        holdout.len()
    );
    search.bar.set_message("baselines");
    let idx: Vec<usize> = base_cands.iter().map(|(_, i)| *i).collect();
    let mut best = search.race("start", &idx, &seeds)?;
    for pass in 0..a.passes {
        let mut changed = false;
        for (pi, p) in points.iter().enumerate() {
            if a.keep.contains(p) {
                continue;
            }
            search
                .bar
                .set_message(format!("pass {} point {p}", pass + 1));
            let mut cands = vec![best];
            for o in options(kinds[pi], &search.scenario, &search.base) {
                if o == search.candidates[best].bindings[pi] {
                    continue;
                }
                let mut b = search.candidates[best].bindings.clone();
                b[pi] = o.clone();
                let label = format!("{p} = {o}");
                if let Some(i) = search.candidate(&label, b)
                    && !cands.contains(&i)
                {
                    cands.push(i);
                }
            }
            if cands.len() < 2 {
                continue;
            }
            let w = search.race(&format!("pass {}, point {p}", pass + 1), &cands, &seeds)?;
            if w != best {
                changed = true;
                best = w;
            }
        }
        if !changed {
            break;
        }
    }
    // The held-out comparison.
    search.bar.set_message("held-out seeds");
    let mut compared: Vec<(String, usize)> = vec![("tuned".to_string(), best)];
    for (l, i) in &base_cands {
        compared.push((l.clone(), *i));
    }
    let all: Vec<usize> = compared.iter().map(|x| x.1).collect();
    search.evaluate(&all, &holdout)?;
    search.bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();

    // The best configuration as a file.
    let (score, success) = search.score(best, &seeds);
    let description = format!(
        "found by `bite tune {}`: {} = {score:.3} over search seeds {} ({:.0} % completed)",
        a.mission.display(),
        search.objective,
        a.seeds,
        success * 100.0
    );
    let best_text = format!(
        "# {description}\n#\n#   bite run {} --config {}\n{}",
        a.mission.display(),
        out.join("best.yaml").display(),
        config_text(
            &format!("tuned-{name}"),
            &description,
            &points,
            &search.candidates[best].bindings
        )
    );
    std::fs::write(out.join("best.yaml"), &best_text)
        .with_context(|| format!("writing {}", out.join("best.yaml").display()))?;
    // Every run of the search.
    let mut csv = String::from(
        "candidate,label,seed,holdout,completed,objective,task_time,messages.total,interaction_time.total\n",
    );
    for ((c, seed), row) in &search.results {
        let f = |k: &str| row.get(k).map(ToString::to_string).unwrap_or_default();
        csv.push_str(&format!(
            "{c},\"{}\",{seed},{},{},{},{},{},{}\n",
            search.candidates[*c].label.replace('"', "\"\""),
            holdout.contains(seed),
            f("completed"),
            search
                .objective
                .of(row)
                .map(|v| v.to_string())
                .unwrap_or_default(),
            f("task_time"),
            f("messages.total"),
            f("interaction_time.total"),
        ));
    }
    std::fs::write(out.join("tune.csv"), csv)
        .with_context(|| format!("writing {}", out.join("tune.csv").display()))?;
    let table = holdout_table(&search, &compared, &holdout);
    let mut report = format!(
        "# Tuning `{}`\n\n{} runs in {wall:.1} s on {jobs} threads. Objective: {} (lower is better), \
         at least {:.0} % of runs completed. Search seeds `{}`; held-out seeds `{}`.\n\n## The search\n\n",
        a.mission.display(),
        search.runs,
        search.objective,
        a.min_success * 100.0,
        a.seeds,
        a.holdout
    );
    for t in &search.trace {
        report.push_str(&format!("- {t}\n"));
    }
    report.push_str(&format!(
        "\n## The best configuration (`best.yaml`)\n\n```yaml\n{}```\n\n{table}",
        config_text(
            &format!("tuned-{name}"),
            &description,
            &points,
            &search.candidates[best].bindings
        )
    ));
    std::fs::write(out.join("report.md"), &report)
        .with_context(|| format!("writing {}", out.join("report.md").display()))?;
    for t in &search.trace {
        outln!("{t}");
    }
    outln!("\nbest: {}", out.join("best.yaml").display());
    for (p, b) in points.iter().zip(&search.candidates[best].bindings) {
        outln!("  {p}: {b}");
    }
    outln!("\n{table}");
    outln!(
        "{} runs in {wall:.1} s; report in {}",
        search.runs,
        out.join("report.md").display()
    );
    Ok(ExitCode::SUCCESS)
}

/// The held-out comparison, as a Markdown table.
fn holdout_table(s: &Search<'_>, compared: &[(String, usize)], seeds: &[u64]) -> String {
    let mut t = format!(
        "### On the holdout seeds ({} seeds the search never saw)\n\n| configuration | runs | completed | {} | task time | messages | Δ vs tuned (95 % CI) |\n|---|---:|---:|---:|---:|---:|---|\n",
        seeds.len(),
        s.objective
    );
    let values = |c: usize, f: &dyn Fn(&Map<String, Json>) -> Option<f64>| -> Vec<f64> {
        seeds
            .iter()
            .filter_map(|x| s.results.get(&(c, *x)))
            .filter_map(f)
            .collect()
    };
    let tuned = values(compared[0].1, &|r| s.objective.of(r));
    for (label, c) in compared {
        let obj = values(*c, &|r| s.objective.of(r));
        let task = values(*c, &|r| r.get("task_time").and_then(Json::as_f64));
        let msgs = values(*c, &|r| r.get("messages.total").and_then(Json::as_f64));
        let (_, success) = (0.0, {
            let ok = seeds
                .iter()
                .filter_map(|x| s.results.get(&(*c, *x)))
                .filter(|r| r.get("completed").and_then(Json::as_bool) == Some(true))
                .count();
            ok as f64 / seeds.len().max(1) as f64
        });
        let d = |v: &[f64]| {
            let d = stats::describe(v);
            format!("{:.2} ± {:.2}", d.mean, d.ci95)
        };
        let delta = if *c == compared[0].1 {
            "—".to_string()
        } else {
            let cmp = stats::compare(&tuned, &obj, fnv(label.as_bytes()));
            format!("{:+.2} [{:+.2}, {:+.2}]", cmp.diff, cmp.ci.0, cmp.ci.1)
        };
        t.push_str(&format!(
            "| {label} | {} | {:.0} % | {} | {} | {} | {delta} |\n",
            obj.len(),
            success * 100.0,
            d(&obj),
            d(&task),
            d(&msgs)
        ));
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objectives_parse_with_weights_and_short_names() {
        let o = Objective::parse("task_time=1, messages=0.5").unwrap();
        assert_eq!(
            o.0,
            vec![
                ("task_time".to_string(), 1.0),
                ("messages.total".to_string(), 0.5)
            ]
        );
        assert_eq!(o.to_string(), "task_time + 0.5 × messages.total");
        let mut row = Map::new();
        row.insert("task_time".into(), Json::from(10.0));
        row.insert("messages.total".into(), Json::from(4));
        assert_eq!(o.of(&row), Some(12.0));
        assert!(
            Objective::parse("task_tme")
                .unwrap_err()
                .contains("did you mean")
        );
        assert!(Objective::parse("task_time=x").is_err());
        assert!(Objective::parse("").is_err());
    }

    #[test]
    fn bindings_are_written_as_a_configuration_reads_them() {
        assert_eq!(binding_yaml("sync.vote", &Json::Null), "sync.vote");
        let b = binding_yaml(
            "alloc.by-value",
            &serde_json::json!({"value": "head_angle"}),
        );
        assert_eq!(
            b,
            "{ protocol: alloc.by-value, params: { value: head_angle } }"
        );
        assert_eq!(
            flow(&serde_json::json!({"wants": {"lead": "red team", "n": 2}, "on": "on"})),
            "{ wants: { lead: \"red team\", n: 2 }, \"on\": \"on\" }"
        );
        let text = config_text("t", "d", &["A".to_string()], &vec![b]);
        let cfg = Config::load_str(&Arc::from("t.yaml"), &text).expect("a configuration");
        assert_eq!(cfg.points().collect::<Vec<_>>(), ["A"]);
    }
}
