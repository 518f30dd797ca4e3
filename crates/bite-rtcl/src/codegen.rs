//! Code generation: checked commands to a BITE behavior graph, the skills
//! (motor schemas) its atomic behaviors run, the beliefs its conditions
//! read and the targets its results designate.
//!
//! The graph is the paper's O = ⟨B1, ..., Bn⟩: a root team behavior
//! `mission` whose only child is the first command's behavior, each command
//! linked by `next` to the following one, so each starts when the previous
//! one has ended (its `until`). A command's behavior decomposes into its
//! minimum behavior set B_x, as its library entry says: one team behavior
//! per phase (chained by `next` under a team behavior for the command when
//! there are several), each either running a skill with the whole team or
//! splitting the team among children (an allocation point). Every team
//! behavior is a termination point: the team ends it together.

use crate::check::Step;
use crate::library::{Body, ChildDef, CommandDef, Library, PhaseDef, SchemaDef};
use crate::source::{SourceMap, printable};
use crate::template::{Env, EvalError, Json, Template, Val, fmt_num};
use crate::{CompileOptions, Compiled, StepInfo, Target};
use bite_core::diag::{Diagnostic, Loc};
use bite_core::graph::BehaviorEntry;
use bite_core::graph::spec::{
    BehaviorSpec, BindingSpec, DefaultsSpec, GraphSpec, MembersSpec, Ordered, RobotsSpec,
    SkillSpec, TeamSpec, WorldModelSpec,
};
use bite_core::ids::name_hash;
use bite_core::wm::Policy;
use serde_saphyr::{Location, Spanned};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

/// One behavior of the generated graph.
#[derive(Clone, Debug, Default, PartialEq)]
struct Beh {
    name: String,
    description: Option<String>,
    team: bool,
    /// Edges, as the loader reads them (made so once).
    children: Vec<Spanned<String>>,
    next: Vec<Spanned<String>>,
    until: Option<String>,
    skill: Option<String>,
    members: Option<MembersSpec>,
    critical: bool,
    terminate: Option<String>,
    /// A later step of a child's chain (not a child itself).
    chained: bool,
}

/// The variables of one command, as its templates see them.
struct StepEnv<'a> {
    def: &'a CommandDef,
    step: &'a str,
    index: usize,
    result: &'a str,
    robots: f64,
    /// Per parameter: the value written, else its default; coordinates
    /// with the origin added.
    params: Vec<Option<Val>>,
    lets: BTreeMap<&'a str, Val>,
    repeat: Option<(f64, f64)>,
    /// Beliefs the rendered templates used.
    used: BTreeSet<&'a str>,
}

/// What a variable of a command is.
enum Found<'a> {
    /// A value (borrowed where the command holds it).
    Val(std::borrow::Cow<'a, Val>),
    /// Text made of the step's name and this (`find_1` and `found`).
    Named(&'a str, &'a str),
}

impl StepEnv<'_> {
    fn find(&mut self, name: &str) -> Option<Found<'_>> {
        use std::borrow::Cow::{Borrowed, Owned};
        let own = |v| Some(Found::Val(Owned(v)));
        match name {
            "step" => return own(Val::Text(self.step.to_string())),
            "index" => return own(Val::Num(self.index as f64)),
            "result" => return own(Val::Text(self.result.to_string())),
            "robots" => return own(Val::Num(self.robots)),
            "i" => return self.repeat.and_then(|(i, _)| own(Val::Num(i))),
            "n" => return self.repeat.and_then(|(_, n)| own(Val::Num(n))),
            _ => {}
        }
        let def = self.def;
        if let Some(i) = def.params.iter().position(|p| p.name == name) {
            return self.params[i].as_ref().map(|v| Found::Val(Borrowed(v)));
        }
        if let Some((_, [x, y])) = def.points.iter().find(|(p, _)| p == name) {
            let get = |n: &str| {
                def.params
                    .iter()
                    .position(|p| p.name == n)
                    .and_then(|i| match &self.params[i] {
                        Some(Val::Num(v)) => Some(*v),
                        _ => None,
                    })
            };
            return own(Val::Point([get(x)?, get(y)?]));
        }
        if let Some(v) = self.lets.get(name) {
            return Some(Found::Val(Borrowed(v)));
        }
        if let Some((b, _)) = def.beliefs.iter().find(|(b, _)| b == name) {
            self.used.insert(b.as_str());
            return Some(Found::Named(self.step, b));
        }
        None
    }
}

impl Env for StepEnv<'_> {
    fn get(&mut self, name: &str) -> Option<Val> {
        self.get_cow(name).map(std::borrow::Cow::into_owned)
    }

    fn get_cow(&mut self, name: &str) -> Option<std::borrow::Cow<'_, Val>> {
        Some(match self.find(name)? {
            Found::Val(v) => v,
            Found::Named(a, b) => std::borrow::Cow::Owned(Val::Text([a, "_", b].concat())),
        })
    }

    fn write(&mut self, name: &str, out: &mut String) -> Option<()> {
        // Names are written in place, not made and copied.
        match name {
            "step" => out.push_str(self.step),
            "result" => out.push_str(self.result),
            _ => match self.find(name)? {
                Found::Val(v) => v.write_text(out),
                Found::Named(a, b) => out.extend([a, "_", b]),
            },
        }
        Some(())
    }
}

/// Generate everything for the checked steps.
///
/// Commands are generated side by side (on rayon's pool, from
/// [`PARALLEL_FROM`] commands), each on its own, then put together in
/// the mission's order: names are checked for duplicates and the graph's
/// size bounded in that order, so the graph, the skills and every message
/// are the same as generating one command after the other, for any number
/// of threads.
pub fn generate(
    map: &SourceMap<'_>,
    steps: &[Step],
    lib: &Library,
    opts: &CompileOptions,
) -> Result<Compiled, Vec<Diagnostic>> {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    let g = Gen { map, lib, opts };
    // The behaviors, one list per command (the mission's own first), kept
    // where each command's thread made them.
    let mut parts = vec![vec![entry(Beh {
        name: "mission".into(),
        description: Some(format!(
            "the mission: {} command{}, in order",
            steps.len(),
            if steps.len() == 1 { "" } else { "s" }
        )),
        team: true,
        ..Beh::default()
    })]];
    // Generated ahead, side by side. Once more behaviors than a graph may
    // have are made, the rest are skipped (`None`): the mission fails
    // (too large, or a duplicate name cut a command short), and those the
    // merge below still reaches are made then, so the messages are the same.
    let made = AtomicUsize::new(parts[0].len());
    // What each command gives the world (skills, beliefs, its target) is
    // split from its behaviors where it is made: the two are put together
    // side by side below.
    let ahead = |s: &Step| -> (Option<StepOut>, Option<World>) {
        let Some(def) = lib.command(&s.command) else {
            return (None, None);
        };
        if made.load(Ordering::Relaxed) > bite_core::graph::MAX_BEHAVIORS {
            return (None, None);
        }
        let mut out = g.step(s, def);
        made.fetch_add(out.entries.len(), Ordering::Relaxed);
        let world = World {
            skills: std::mem::take(&mut out.skills),
            beliefs: std::mem::take(&mut out.beliefs),
            target: out.target.take(),
        };
        (Some(out), Some(world))
    };
    let parallel = steps.len() >= PARALLEL_FROM;
    let (mut outs, worlds): (Vec<Option<StepOut>>, Vec<Option<World>>) = if parallel {
        steps.par_iter().map(ahead).unzip()
    } else {
        steps.iter().map(ahead).unzip()
    };
    let made = made.into_inner();
    // The behaviors, in the mission's order: names checked for
    // duplicates, the graph's size bounded.
    let merge = move || -> Result<Merged, Vec<Diagnostic>> {
        parts.reserve(steps.len());
        // Names taken so far, as places in `parts` (no copy of a name).
        let mut names: hashbrown::HashTable<(u32, u32)> =
            hashbrown::HashTable::with_capacity(made + 1);
        names.insert_unique(name_hash("mission"), (0, 0), |_| name_hash("mission"));
        let mut count = parts[0].len();
        let mut infos = Vec::with_capacity(steps.len());
        let mut diags = Vec::new();
        let mut warnings = Vec::new();
        let mut heads = Vec::with_capacity(steps.len());
        for (s, out) in steps.iter().zip(&mut outs) {
            let Some(def) = lib.command(&s.command) else {
                continue;
            };
            // A command skipped ahead is made now (its world is not needed:
            // the mission fails).
            let mut out = out.take().unwrap_or_else(|| g.step(s, def));
            warnings.append(&mut out.warnings);
            let head = parts.len();
            parts.push(out.entries);
            // Its behaviors in order, up to the first name already taken.
            let mut failed = None;
            let name = |&(c, i): &(u32, u32)| &parts[c as usize][i as usize].0.value;
            for (j, &h) in out.hashes.iter().enumerate() {
                let at = (head as u32, j as u32);
                let taken = |p: &(u32, u32)| name(p) == name(&at);
                match names.entry(h, taken, |p| name_hash(name(p))) {
                    hashbrown::hash_table::Entry::Occupied(_) => {
                        let msg = format!("two behaviors would be called `{}`", name(&at));
                        failed = Some((j, g.lib_error(s, def, def.loc, msg)));
                        break;
                    }
                    hashbrown::hash_table::Entry::Vacant(v) => {
                        v.insert(at);
                    }
                }
            }
            if let Some((j, _)) = failed {
                parts[head].truncate(j);
            }
            count += parts[head].len();
            match failed.map_or(out.result, |(_, d)| Err(d)) {
                Ok(name) => {
                    heads.push((head, name));
                    infos.extend(out.info);
                }
                Err(d) => diags.push(*d),
            }
            if count > bite_core::graph::MAX_BEHAVIORS {
                diags.push(Diagnostic::error(
                    map.file(),
                    Loc::UNKNOWN,
                    "too-large",
                    format!(
                        "the mission needs more than {} behaviors, the most a graph may have",
                        bite_core::graph::MAX_BEHAVIORS
                    ),
                ));
                break;
            }
        }
        if !diags.is_empty() {
            return Err(diags);
        }
        Ok(Merged {
            parts,
            count,
            heads,
            infos,
            warnings,
        })
    };
    // Skills, beliefs and targets in the mission's order, put in their
    // maps: sorted once (a later one with the same name replaces an
    // earlier, as inserting one after the other would). Only a mission
    // that compiles uses them, and then every command was made ahead.
    let maps = move || {
        let total = |f: fn(&World) -> usize| worlds.iter().flatten().map(f).sum::<usize>();
        // Their sizes are known: no list grows by copies onto fresh pages.
        let mut skills = Vec::with_capacity(total(|w| w.skills.len()));
        let mut beliefs = Vec::with_capacity(total(|w| w.beliefs.len()));
        let mut targets = Vec::with_capacity(total(|w| usize::from(w.target.is_some())));
        for w in worlds.into_iter().flatten() {
            skills.extend(w.skills);
            beliefs.extend(w.beliefs);
            targets.extend(w.target);
        }
        (
            sorted_map(skills, parallel),
            sorted_map(beliefs, parallel),
            sorted_map(targets, parallel),
        )
    };
    let (merged, (skills, beliefs, targets)) = if parallel {
        rayon::join(merge, maps)
    } else {
        (merge(), maps())
    };
    let Merged {
        mut parts,
        count,
        heads,
        infos,
        warnings,
    } = merged?;
    // The chain: mission → B1 → B2 → ... → Bn (each name is one edge's:
    // moved there).
    let mut before: Option<usize> = None;
    for (head, name) in heads {
        match before {
            None => parts[0][0].1.value.children.push(at(name)),
            Some(b) => parts[b][0].1.value.next.push(at(name)),
        }
        before = Some(head);
    }
    // What the robots tell each other: what any command needs (the
    // library's few commands are asked, not every step).
    let sharing = lib
        .commands
        .values()
        .filter(|d| d.sharing != Policy::None)
        .filter(|d| steps.iter().any(|s| s.command == d.name))
        .fold(Policy::None, |p, d| p.union(d.sharing));
    let generated = GeneratedGraph {
        sharing,
        name: printable(&stem(map.file())),
        file: printable(map.file()),
        commands: steps.len(),
        origin: opts.origin,
        robots: opts.robots,
        parts,
        len: count,
    };
    Ok(Compiled {
        generated,
        skills,
        beliefs,
        targets,
        steps: infos,
        warnings,
    })
}

/// A map of `pairs`, the last of equal keys kept (as inserting them in
/// order would); sorted on rayon's pool when `parallel`.
///
/// What is sorted is each name's first 16 bytes as a number, with its
/// place: most comparisons are of two numbers, not of two names somewhere
/// in memory, and no pair is moved until its place is known.
fn sorted_map<V: Send + Sync>(pairs: Vec<(String, V)>, parallel: bool) -> BTreeMap<String, V> {
    let mut keys: Vec<(u128, u32)> = (pairs.iter().enumerate())
        .map(|(i, (k, _))| (name_prefix(k), i as u32))
        .collect();
    // Equal names stay in order (by place), and the map keeps the last.
    let order = |a: &(u128, u32), b: &(u128, u32)| {
        (a.0.cmp(&b.0))
            .then_with(|| pairs[a.1 as usize].0.cmp(&pairs[b.1 as usize].0))
            .then(a.1.cmp(&b.1))
    };
    if parallel {
        use rayon::prelude::*;
        keys.par_sort_unstable_by(order);
    } else {
        keys.sort_unstable_by(order);
    }
    let mut slots: Vec<Option<(String, V)>> = pairs.into_iter().map(Some).collect();
    keys.iter()
        .filter_map(|&(_, i)| slots[i as usize].take())
        .collect()
}

/// A name's first 16 bytes as a big-endian number (zeros after a shorter
/// name): two names compare as their prefixes do, unless those are equal.
fn name_prefix(name: &str) -> u128 {
    let mut b = [0u8; 16];
    let n = name.len().min(16);
    b[..n].copy_from_slice(&name.as_bytes()[..n]);
    u128::from_be_bytes(b)
}

/// Missions of this many commands or more are generated on rayon's pool;
/// shorter ones on the calling thread (the result is the same).
pub const PARALLEL_FROM: usize = 32;

/// What the commands are generated with.
struct Gen<'a, 's> {
    map: &'a SourceMap<'s>,
    lib: &'a Library,
    opts: &'a CompileOptions,
}

/// What one command gives the world.
struct World {
    skills: Vec<(String, Vec<Json>)>,
    beliefs: Vec<(String, String)>,
    target: Option<(String, Target)>,
}

/// The commands' behaviors put together in order.
struct Merged {
    parts: Vec<Vec<BehaviorEntry>>,
    /// Number of behaviors.
    count: usize,
    /// Each command's first list in `parts`, and its behavior's name.
    heads: Vec<(usize, String)>,
    infos: Vec<StepInfo>,
    warnings: Vec<Diagnostic>,
}

/// What one command generated, in the order the sequential generator made
/// it; names are checked for duplicates when the commands are put together.
struct StepOut {
    /// Its behaviors, its own first; up to the failure if it failed.
    behs: Vec<Beh>,
    /// The same as the graph loader reads them (made from `behs` at the end).
    entries: Vec<BehaviorEntry>,
    /// Their names' hashes ([`name_hash`]), made beside them: the merge
    /// then reads no name unless two hashes are equal.
    hashes: Vec<u64>,
    skills: Vec<(String, Vec<Json>)>,
    beliefs: Vec<(String, String)>,
    target: Option<(String, Target)>,
    info: Option<StepInfo>,
    warnings: Vec<Diagnostic>,
    /// Its behavior's name, or why the rest could not be generated.
    result: Result<String, Box<Diagnostic>>,
}

impl Gen<'_, '_> {
    /// A library entry that cannot be generated for this command.
    fn lib_error(
        &self,
        s: &Step,
        def: &CommandDef,
        at: Loc,
        what: impl Into<String>,
    ) -> Box<Diagnostic> {
        let mut d = self.map.error(
            s.span,
            "library",
            format!(
                "the library's `{}` cannot be generated for this command: {}",
                def.name,
                what.into()
            ),
        );
        d.hint = Some(if at.is_known() {
            format!("see {}:{}:{}", self.lib.file, at.line, at.col)
        } else {
            format!("see `{}` in {}", def.name, self.lib.file)
        });
        Box::new(d)
    }

    fn render(
        &self,
        s: &Step,
        def: &CommandDef,
        at: Loc,
        t: &Template,
        env: &mut StepEnv<'_>,
    ) -> Result<String, Box<Diagnostic>> {
        t.render(env).map_err(|e| self.eval_error(s, def, at, &e))
    }

    fn eval_error(&self, s: &Step, def: &CommandDef, at: Loc, e: &EvalError) -> Box<Diagnostic> {
        self.lib_error(s, def, at, e.to_string())
    }

    fn schemas(
        &self,
        s: &Step,
        def: &CommandDef,
        list: &[SchemaDef],
        env: &mut StepEnv<'_>,
    ) -> Result<Vec<Json>, Box<Diagnostic>> {
        let mut out = Vec::new();
        for sc in list {
            if sc.guard.as_ref().is_none_or(|g| g.holds(env)) {
                out.push(
                    sc.template
                        .render(env)
                        .map_err(|e| self.eval_error(s, def, sc.loc, &e))?,
                );
            }
        }
        Ok(out)
    }

    /// Generate one command on its own.
    fn step(&self, s: &Step, def: &CommandDef) -> StepOut {
        let mut out = StepOut {
            behs: Vec::new(),
            entries: Vec::new(),
            hashes: Vec::new(),
            skills: Vec::new(),
            beliefs: Vec::new(),
            target: None,
            info: None,
            warnings: Vec::new(),
            result: Ok(String::new()),
        };
        out.result = self.step_into(s, def, &mut out);
        out.hashes = out.behs.iter().map(|b| name_hash(&b.name)).collect();
        out.entries = std::mem::take(&mut out.behs)
            .into_iter()
            .map(entry)
            .collect();
        out
    }

    /// Generate one command into `out`; returns the name of its behavior.
    fn step_into(
        &self,
        s: &Step,
        def: &CommandDef,
        out: &mut StepOut,
    ) -> Result<String, Box<Diagnostic>> {
        // Texts made at their size (`format!` grows them from nothing).
        let sized = |n: usize, args: std::fmt::Arguments<'_>| {
            let mut t = String::with_capacity(n);
            let _ = t.write_fmt(args);
            t
        };
        let step = sized(def.name.len() + 8, format_args!("{}_{}", def.name, s.index));
        let result: &str = s.result.as_deref().unwrap_or(&step);
        if self.opts.robots < def.min_robots {
            out.warnings.push(
                self.map
                    .warning(
                        s.span,
                        "too-few-robots",
                        format!(
                            "`{}` needs a team of {} robots or more; this one has {}",
                            def.name, def.min_robots, self.opts.robots
                        ),
                    )
                    .with_hint(format!(
                        "part of its decomposition may get no robot (see `{}` in {})",
                        def.name, self.lib.file
                    )),
            );
        }
        let mut params = Vec::with_capacity(def.params.len());
        for (p, v) in def.params.iter().zip(&s.values) {
            let v = v.clone().or_else(|| p.default.clone());
            let v = match (&p.ty, v) {
                (crate::library::ParamType::X, Some(Val::Num(x))) => {
                    Some(Val::Num(x + self.opts.origin[0]))
                }
                (crate::library::ParamType::Y, Some(Val::Num(y))) => {
                    Some(Val::Num(y + self.opts.origin[1]))
                }
                (_, v) => v,
            };
            params.push(v);
        }
        let mut env = StepEnv {
            def,
            step: &step,
            index: s.index,
            result,
            robots: self.opts.robots as f64,
            params,
            lets: BTreeMap::new(),
            repeat: None,
            used: BTreeSet::new(),
        };
        for (name, t) in &def.lets {
            // A value that cannot be computed stays unknown; it is an
            // error only where it is used.
            if let Ok(v) = t.value(&mut env) {
                env.lets.insert(name.as_str(), v);
            }
        }
        let phases: Vec<&PhaseDef> = def
            .phases
            .iter()
            .filter(|p| p.guard.as_ref().is_none_or(|g| g.holds(&mut env)))
            .collect();
        if phases.is_empty() {
            return Err(self.lib_error(s, def, def.loc, "no phase applies (check their `if`)"));
        }
        let description = Some(sized(
            s.text.len() + 16,
            format_args!("line {}: {}", s.line, s.text),
        ));
        let single = phases.len() == 1;
        if !single {
            let until = match &def.until {
                Some(t) => Some(self.render(s, def, def.loc, t, &mut env)?),
                None => None,
            };
            out.behs.push(Beh {
                name: step.clone(),
                description: description.clone(),
                team: true,
                children: vec![at([&step, "_", &phases[0].name].concat())],
                until,
                ..Beh::default()
            });
        }
        for (k, ph) in phases.iter().enumerate() {
            let name = if single {
                step.clone()
            } else {
                [&step, "_", &ph.name].concat()
            };
            let until_t = ph
                .until
                .as_ref()
                .or(if single { def.until.as_ref() } else { None });
            let until = match until_t {
                Some(t) => Some(self.render(s, def, ph.loc, t, &mut env)?),
                None => None,
            };
            let pdesc = match &ph.description {
                Some(t) => Some(self.render(s, def, ph.loc, t, &mut env)?),
                None => None,
            };
            let description = if single {
                match pdesc {
                    Some(p) => Some(sized(
                        s.text.len() + p.len() + 20,
                        format_args!("line {}: {} - {p}", s.line, s.text),
                    )),
                    None => description.clone(),
                }
            } else {
                pdesc
            };
            let next = phases
                .get(k + 1)
                .map(|p| vec![at([&step, "_", &p.name].concat())])
                .unwrap_or_default();
            let mut beh = Beh {
                name: name.clone(),
                description,
                team: true,
                next,
                until,
                terminate: ph.terminate.clone(),
                ..Beh::default()
            };
            match &ph.body {
                Body::Skill(list) => {
                    let schemas = self.schemas(s, def, list, &mut env)?;
                    out.skills.push((name.clone(), schemas));
                    beh.skill = Some(name.clone());
                    out.behs.push(beh);
                }
                Body::Split(children) => {
                    let kids = self.children(s, def, &step, children, &mut env, out)?;
                    if kids.iter().all(|k| k.chained) {
                        return Err(self.lib_error(
                            s,
                            def,
                            ph.loc,
                            format!("phase `{}` has no child for this command", ph.name),
                        ));
                    }
                    beh.children = kids
                        .iter()
                        .filter(|k| !k.chained)
                        .map(|k| at(k.name.clone()))
                        .collect();
                    let split = beh.children.len() > 1;
                    out.behs.push(beh);
                    for mut kid in kids {
                        if !split {
                            kid.members = None;
                            kid.critical = false;
                        }
                        out.behs.push(kid);
                    }
                }
            }
        }
        // Beliefs the command's conditions read.
        let used: Vec<&str> = env.used.iter().copied().collect();
        for b in used {
            if let Some((_, t)) = def.beliefs.iter().find(|(n, _)| n == b) {
                let cond = self.render(s, def, def.loc, t, &mut env)?;
                out.beliefs.push(([&step, "_", b].concat(), cond));
            }
        }
        // What the result designates.
        if let Some(rd) = &def.result {
            let get = |n: &Option<String>| -> Option<Val> {
                let i = def
                    .params
                    .iter()
                    .position(|p| Some(&p.name) == n.as_ref())?;
                s.values[i].clone()
            };
            let colour = match get(&rd.colour) {
                Some(Val::Text(c)) => Some(c),
                _ => None,
            };
            let size = rd.size.as_ref().and_then(|names| {
                let v: Vec<Option<f64>> = names
                    .iter()
                    .map(|n| match get(&Some(n.clone())) {
                        Some(Val::Num(x)) => Some(x),
                        _ => None,
                    })
                    .collect();
                v.iter().any(Option::is_some).then(|| [v[0], v[1], v[2]])
            });
            out.target = Some((result.to_string(), Target { colour, size }));
        }
        out.info = Some(StepInfo {
            index: s.index,
            line: s.line,
            command: def.name.clone(),
            behavior: step.clone(),
            behaviors: out.behs.iter().map(|b| b.name.clone()).collect(),
            result: s.result.clone(),
        });
        Ok(step)
    }

    fn children(
        &self,
        s: &Step,
        def: &CommandDef,
        step: &str,
        children: &[ChildDef],
        env: &mut StepEnv<'_>,
        step_out: &mut StepOut,
    ) -> Result<Vec<Beh>, Box<Diagnostic>> {
        let mut out = Vec::new();
        for ch in children {
            if !ch.guard.as_ref().is_none_or(|g| g.holds(env)) {
                continue;
            }
            let copies = match &ch.repeat {
                None => None,
                Some(t) => {
                    let v = t
                        .value(env)
                        .map_err(|e| self.eval_error(s, def, ch.loc, &e))?;
                    match v {
                        Val::Num(n) if n.fract() == 0.0 && (0.0..=10_000.0).contains(&n) => Some(n),
                        other => {
                            return Err(self.lib_error(
                                s,
                                def,
                                ch.loc,
                                format!(
                                    "`repeat` of `{}` is `{}`, not a count from 0 to 10000",
                                    ch.name,
                                    other.to_text()
                                ),
                            ));
                        }
                    }
                }
            };
            let instances: Vec<Option<(f64, f64)>> = match copies {
                None => vec![None],
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                Some(n) => (1..=n as u64).map(|i| Some((i as f64, n))).collect(),
            };
            for inst in instances {
                env.repeat = inst;
                let name = match inst {
                    None => [step, "_", &ch.name].concat(),
                    Some((i, _)) => [step, "_", &ch.name, "_", &fmt_num(i)].concat(),
                };
                let until = match &ch.until {
                    Some(t) => Some(self.render(s, def, ch.loc, t, env)?),
                    None => None,
                };
                let description = match &ch.description {
                    Some(t) => Some(self.render(s, def, ch.loc, t, env)?),
                    None => None,
                };
                let schemas = self.schemas(s, def, &ch.skill, env)?;
                step_out.skills.push((name.clone(), schemas));
                let chain_name = |t: &str| match inst {
                    None => [step, "_", t].concat(),
                    Some((i, _)) => [step, "_", t, "_", &fmt_num(i)].concat(),
                };
                out.push(Beh {
                    name: name.clone(),
                    description,
                    team: false,
                    until,
                    skill: Some(name),
                    members: ch.members,
                    critical: ch.critical,
                    next: ch
                        .then
                        .first()
                        .map(|t| vec![at(chain_name(&t.name))])
                        .unwrap_or_default(),
                    ..Beh::default()
                });
                // The rest of its execution chain.
                for (k, t) in ch.then.iter().enumerate() {
                    let name = chain_name(&t.name);
                    let until = match &t.until {
                        Some(u) => Some(self.render(s, def, t.loc, u, env)?),
                        None => None,
                    };
                    let description = match &t.description {
                        Some(d) => Some(self.render(s, def, t.loc, d, env)?),
                        None => None,
                    };
                    let schemas = self.schemas(s, def, &t.skill, env)?;
                    step_out.skills.push((name.clone(), schemas));
                    out.push(Beh {
                        name: name.clone(),
                        description,
                        until,
                        skill: Some(name),
                        next: ch
                            .then
                            .get(k + 1)
                            .map(|n| vec![at(chain_name(&n.name))])
                            .unwrap_or_default(),
                        chained: true,
                        ..Beh::default()
                    });
                }
            }
            env.repeat = None;
        }
        Ok(out)
    }
}

/// The graph's name: the mission file's stem.
fn stem(file: &str) -> String {
    std::path::Path::new(file).file_stem().map_or_else(
        || "mission".to_string(),
        |s| s.to_string_lossy().into_owned(),
    )
}

/// A value without a place in a file (the generated graph has none).
fn at<T>(value: T) -> Spanned<T> {
    Spanned::new(value, Location::UNKNOWN, Location::UNKNOWN)
}

/// A generated behavior as the graph loader reads it.
fn entry(b: Beh) -> BehaviorEntry {
    let spec = BehaviorSpec {
        description: b.description,
        team: b.team,
        children: b.children,
        next: b.next,
        until: b.until.map(|u| Box::new(at(u))),
        skill: b.skill.map(|name| {
            Box::new(at(SkillSpec {
                name,
                params: BTreeMap::new(),
            }))
        }),
        members: b.members.map(at),
        critical: b.critical.then(|| at(true)),
        terminate: b.terminate.map(|p| {
            Box::new(at(BindingSpec {
                protocol: Some(p),
                ..BindingSpec::default()
            }))
        }),
        ..BehaviorSpec::default()
    };
    (at(b.name), at(spec))
}

/// The generated graph as data: the graph [`Compiled::graph`] writes in
/// YAML, to hand to the graph loader without writing and parsing text
/// ([`Compiled::load_graph`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GeneratedGraph {
    name: String,
    /// The mission file, printable.
    file: String,
    /// Commands compiled.
    commands: usize,
    origin: [f64; 2],
    robots: usize,
    /// What the robots tell each other (`world_model: { sharing: ... }`).
    sharing: Policy,
    /// The behaviors as the loader reads them (it reads them in place),
    /// one list per command, where its thread made them; the mission's own
    /// first.
    parts: Vec<Vec<BehaviorEntry>>,
    /// Number of behaviors.
    len: usize,
}

impl GeneratedGraph {
    /// Number of behaviors.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when it has no behavior (never for a compiled mission).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The behaviors in order, as [`bite_core::graph::load_parts`] reads
    /// them.
    pub fn behaviors(&self) -> Vec<&BehaviorEntry> {
        self.parts.iter().flatten().collect()
    }

    /// The graph in YAML, the `bite-core` format, with a header comment
    /// naming the mission file ([`Compiled::graph`]).
    pub fn yaml(&self) -> String {
        let file = &self.file;
        let commands = self.commands;
        let mut y = String::with_capacity(self.len * 160 + 512);
        let _ = writeln!(
            y,
            "# Generated by bite-rtcl from {file} ({commands} command{}); do not edit:\n\
             # change the mission and compile it again.\n\
             # Mission origin [{}, {}] (the mission's coordinates are relative to it); {} robots.",
            if commands == 1 { "" } else { "s" },
            fmt_num(self.origin[0]),
            fmt_num(self.origin[1]),
            self.robots
        );
        let _ = writeln!(y, "graph: {}", scalar(&self.name));
        let _ = writeln!(y, "description: {}", quote(&self.description()));
        let _ = writeln!(y, "team:\n  robots: {}", self.robots);
        y.push_str("start: mission\n");
        y.push_str(
            "defaults:\n  sync: sync.by-rule\n  allocate: alloc.by-id\n  terminate: term.wait-all\n",
        );
        if self.sharing != Policy::None {
            let _ = writeln!(y, "world_model:\n  sharing: {}", self.sharing);
        }
        y.push_str("behaviors:\n");
        let list = |names: &[Spanned<String>]| {
            names
                .iter()
                .map(|n| n.value.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        // A blank line before each command's behaviors.
        let parts = self.parts.iter().enumerate();
        let lists =
            parts.flat_map(|(c, p)| p.iter().enumerate().map(move |(j, b)| (c > 0 && j == 0, b)));
        for (first, (name, b)) in lists {
            let b = &b.value;
            if first {
                y.push('\n');
            }
            let _ = writeln!(y, "  {}:", name.value);
            if let Some(d) = &b.description {
                let _ = writeln!(y, "    description: {}", quote(d));
            }
            if b.team {
                y.push_str("    team: true\n");
            }
            if !b.children.is_empty() {
                let _ = writeln!(y, "    children: [{}]", list(&b.children));
            }
            if let Some(s) = &b.skill {
                let _ = writeln!(y, "    skill: {}", s.value.name);
            }
            if let Some(m) = &b.members {
                let _ = writeln!(y, "    members: {}", members_text(m.value));
            }
            if b.critical.as_ref().is_some_and(|c| c.value) {
                y.push_str("    critical: true\n");
            }
            if let Some(u) = &b.until {
                let _ = writeln!(y, "    until: {}", scalar(&u.value));
            }
            if let Some(p) = b
                .terminate
                .as_ref()
                .and_then(|t| t.value.protocol.as_deref())
            {
                let _ = writeln!(y, "    terminate: {}", scalar(p));
            }
            if !b.next.is_empty() {
                let _ = writeln!(y, "    next: [{}]", list(&b.next));
            }
        }
        y
    }

    /// The graph's description.
    fn description(&self) -> String {
        format!("compiled from {}", self.file)
    }

    /// The graph's spec but its behaviors (read in place:
    /// [`GeneratedGraph::behaviors`]).
    pub fn header(&self) -> GraphSpec {
        let protocol = |p: &str| {
            Some(at(BindingSpec {
                protocol: Some(p.to_string()),
                ..BindingSpec::default()
            }))
        };
        GraphSpec {
            graph: Some(self.name.clone()),
            description: Some(self.description()),
            team: Some(TeamSpec {
                robots: at(RobotsSpec::Count(self.robots as u64)),
            }),
            start: Some(at("mission".to_string())),
            defaults: DefaultsSpec {
                sync: protocol("sync.by-rule"),
                allocate: protocol("alloc.by-id"),
                terminate: protocol("term.wait-all"),
            },
            beliefs: Ordered::default(),
            world_model: (self.sharing != Policy::None).then(|| {
                at(WorldModelSpec {
                    sharing: Some(at(self.sharing.to_string())),
                    hz: None,
                    budget: None,
                })
            }),
            behaviors: None,
        }
    }
}

fn members_text(m: MembersSpec) -> String {
    if m.min == m.max {
        m.min.to_string()
    } else if m.max == u32::MAX {
        format!("\"{}..\"", m.min)
    } else {
        format!("\"{}..{}\"", m.min, m.max)
    }
}

/// A YAML double-quoted string.
pub fn quote(s: &str) -> String {
    let mut q = String::with_capacity(s.len() + 2);
    q.push('"');
    for c in s.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            '\t' => q.push_str("\\t"),
            c if c.is_control() || c == '\u{feff}' || c == '\u{fffe}' || c == '\u{ffff}' => {
                let _ = write!(q, "\\u{:04x}", c as u32);
            }
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

/// A YAML scalar: plain when it is a simple name that YAML reads as text,
/// double-quoted otherwise.
pub fn scalar(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        && !matches!(
            s.to_ascii_lowercase().as_str(),
            "true" | "false" | "null" | "yes" | "no" | "on" | "off" | "y" | "n" | "inf" | "nan"
        );
    if plain { s.to_string() } else { quote(s) }
}

/// A JSON value as YAML flow: `{ schema: wander, speed: 0.25, layer: 1 }`.
pub fn flow(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Null => "null".into(),
        serde_json::Value::Bool(b) => b.to_string(),
        serde_json::Value::Number(n) => n.to_string(),
        serde_json::Value::String(s) => scalar(s),
        serde_json::Value::Array(a) => {
            format!("[{}]", a.iter().map(flow).collect::<Vec<_>>().join(", "))
        }
        serde_json::Value::Object(m) => {
            if m.is_empty() {
                return "{}".into();
            }
            format!(
                "{{ {} }}",
                m.iter()
                    .map(|(k, v)| format!("{}: {}", scalar(k), flow(v)))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CompileOptions, Library, compile};

    proptest::proptest! {
        /// The sorted map is the map made by inserting the pairs in order
        /// (a later equal name replaces an earlier one), on one thread or
        /// on the pool: names that share long prefixes, are prefixes of
        /// each other, hold zero bytes or are not ASCII.
        #[test]
        fn sorted_map_is_inserting_in_order(
            names in proptest::collection::vec("(formation_1|a|\\x00|é){0,6}[a-c]{0,2}", 0..200),
            parallel: bool,
        ) {
            let pairs: Vec<(String, usize)> = names.into_iter().enumerate().map(|(i, n)| (n, i)).collect();
            let mut want = BTreeMap::new();
            for (k, v) in pairs.clone() {
                want.insert(k, v);
            }
            proptest::prop_assert_eq!(sorted_map(pairs, parallel), want);
        }
    }

    fn build(src: &str, robots: usize, origin: [f64; 2]) -> Compiled {
        compile(
            "t.rtcl",
            src,
            &Library::builtin(),
            &CompileOptions { origin, robots },
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    fn lines_of<'a>(graph: &'a str, behavior: &str) -> Vec<&'a str> {
        graph
            .lines()
            .skip_while(|l| *l != format!("  {behavior}:"))
            .skip(1)
            .take_while(|l| l.starts_with("    "))
            .map(str::trim)
            .collect()
    }

    #[test]
    fn commands_chain_in_order_under_the_mission() {
        let out = build("wait:1\ngoto:1:2\nwait:3\n", 2, [0.0, 0.0]);
        assert!(lines_of(&out.graph(), "mission").contains(&"children: [wait_1]"));
        assert!(lines_of(&out.graph(), "wait_1").contains(&"next: [goto_2]"));
        assert!(lines_of(&out.graph(), "goto_2").contains(&"next: [wait_3]"));
        assert!(
            !lines_of(&out.graph(), "wait_3")
                .iter()
                .any(|l| l.starts_with("next"))
        );
        assert_eq!(
            out.steps
                .iter()
                .map(|s| s.behavior.as_str())
                .collect::<Vec<_>>(),
            ["wait_1", "goto_2", "wait_3"]
        );
    }

    #[test]
    fn a_goto_team_stops_in_a_crowd_that_grows_with_the_root_of_its_size() {
        // 0.15 m more for each robot of a small team; from 12 robots on,
        // 0.5·√N: 60 robots are done within 4.17 m of the point, not 9.3.
        let near = |robots: usize| {
            let out = build("goto:0:0\n", robots, [0.0, 0.0]);
            let cond = out.beliefs["goto_1_arrived"].clone();
            let (_, r) = cond.split_once("< ").expect("a distance");
            r.parse::<f64>().expect("a number")
        };
        assert_eq!(near(5), 1.05);
        assert_eq!(near(11), 1.95);
        assert_eq!(near(60), 4.172983346);
        assert!((near(1000) - 16.1114).abs() < 1e-3, "{}", near(1000));
    }

    /// A mission shares what any of its commands needs, in the YAML and
    /// in the graph loaded in place alike; one that needs nothing shares
    /// nothing.
    #[test]
    fn a_mission_shares_what_its_commands_need() {
        let policy = |src: &str, lib: &Library| {
            let out = compile("t.rtcl", src, lib, &CompileOptions::default())
                .unwrap_or_else(|e| panic!("{e}"));
            let file: std::sync::Arc<str> = "t.rtcl".into();
            let in_place = out.load_graph(&file).expect("loads").sharing().policy;
            let text = out.graph();
            let from_yaml = bite_core::graph::load_str(&file, &text)
                .expect("loads")
                .sharing()
                .policy;
            assert_eq!(in_place, from_yaml, "{text}");
            (in_place, text)
        };
        let builtin = Library::builtin();
        let (p, text) = policy("find::::yellow=>box\nmove:box:0:0\n", &builtin);
        assert_eq!(p, Policy::Focused);
        assert!(
            text.contains("world_model:\n  sharing: focused\n"),
            "{text}"
        );
        let (p, text) = policy("goto:1:1\nwait:2\n", &builtin);
        assert_eq!(p, Policy::None);
        assert!(!text.contains("world_model"), "{text}");
        let lib = Library::from_str(
            "lib.yaml",
            "\
commands:
  a:
    sharing: focused
    phases: [{ name: p, skill: [{ schema: stop, layer: 1 }], until: \"elapsed > 1\" }]
  b:
    sharing: helpful
    phases: [{ name: p, skill: [{ schema: stop, layer: 1 }], until: \"elapsed > 1\" }]
  c:
    phases: [{ name: p, skill: [{ schema: stop, layer: 1 }], until: \"elapsed > 1\" }]
",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(policy("a\nc\n", &lib).0, Policy::Focused);
        assert_eq!(policy("b\n", &lib).0, Policy::Helpful);
        assert_eq!(policy("c\nb\na\n", &lib).0, Policy::FocusedHelpful);
        assert_eq!(policy("c\n", &lib).0, Policy::None);
    }

    #[test]
    fn the_origin_moves_every_point() {
        let out = build("goto:1:2\nscan:0:0:2:1\n", 2, [10.0, -1.0]);
        assert_eq!(out.beliefs["goto_1_arrived"], "dist(pos, [11, 1]) < 0.6");
        assert_eq!(
            out.skills["goto_1"][0].to_json()["goal"],
            serde_json::json!([11, 1])
        );
        assert_eq!(
            out.skills["scan_2_lane_2"][0].to_json()["region"],
            serde_json::json!([10, -0.5, 12, 0])
        );
    }

    #[test]
    fn repeated_children_one_per_robot() {
        let out = build("scan:0:0:3:3\n", 3, [0.0, 0.0]);
        assert!(
            lines_of(&out.graph(), "scan_1")
                .contains(&"children: [scan_1_lane_1, scan_1_lane_2, scan_1_lane_3]")
        );
        assert_eq!(
            out.skills["scan_1_lane_3"][0].to_json()["region"],
            serde_json::json!([0, 2, 3, 3])
        );
        // Alone, a robot's single lane is no allocation: no `members`.
        let out = build("scan:0:0:3:3\n", 1, [0.0, 0.0]);
        assert!(
            !lines_of(&out.graph(), "scan_1_lane_1")
                .iter()
                .any(|l| l.starts_with("members"))
        );
    }

    #[test]
    fn guards_pick_the_decomposition() {
        let walk = build("formation:column::4:0\n", 3, [0.0, 0.0]);
        assert!(lines_of(&walk.graph(), "formation_1").contains(&"terminate: term.first-wins"));
        assert_eq!(
            walk.skills["formation_1_rank_2"][0],
            serde_json::json!({"schema": "follow", "of": "formation_1_rank_1", "distance": 0.6, "layer": 1})
        );
        assert!(walk.beliefs.contains_key("formation_1_arrived"));
        let form = build("formation:triangle:0.8\n", 3, [0.0, 0.0]);
        assert!(
            !lines_of(&form.graph(), "formation_1")
                .iter()
                .any(|l| l.starts_with("terminate"))
        );
        assert_eq!(
            form.skills["formation_1_lead"][0].to_json()["schema"],
            "stop"
        );
        assert_eq!(
            form.skills["formation_1_left"][0].to_json()["distance"],
            serde_json::json!(0.8)
        );
        // Only the beliefs the conditions read are generated.
        assert_eq!(
            form.beliefs.keys().collect::<Vec<_>>(),
            ["formation_1_formed"]
        );
    }

    #[test]
    fn unnamed_results_are_named_after_their_command() {
        let out = build("find::::red\n", 2, [0.0, 0.0]);
        assert_eq!(out.targets["find_1"].colour.as_deref(), Some("red"));
        assert_eq!(out.beliefs["find_1_found"], "known(find_1_pos)");
    }

    #[test]
    fn repeated_commands_get_distinct_behaviors() {
        let out = build(
            "find::::red=>a\nmove:a:1:1\nfind::::blue=>b\nmove:b:2:2\n",
            2,
            [0.0, 0.0],
        );
        for b in ["find_1", "move_2_push", "find_3", "move_4_finish_push"] {
            assert!(out.skills.contains_key(b), "{b}");
        }
        assert_eq!(out.targets["b"].colour.as_deref(), Some("blue"));
        assert_eq!(out.beliefs["find_3_found"], "known(b_pos)");
    }

    #[test]
    fn scalars_are_quoted_when_needed() {
        assert_eq!(scalar("find_1_found"), "find_1_found");
        assert_eq!(scalar("term.first-wins"), "term.first-wins");
        assert_eq!(scalar("elapsed >= 3"), "\"elapsed >= 3\"");
        assert_eq!(scalar("yes"), "\"yes\"");
        assert_eq!(scalar(""), "\"\"");
        assert_eq!(quote("a\"b\\c\u{7}"), "\"a\\\"b\\\\c\\u0007\"");
    }

    #[test]
    fn flow_mappings() {
        let v =
            serde_json::json!({"schema": "push", "goal": [6.2, 2], "object": "box", "layer": 2});
        assert_eq!(
            flow(&v),
            "{ schema: push, goal: [6.2, 2], object: box, layer: 2 }"
        );
    }
}
