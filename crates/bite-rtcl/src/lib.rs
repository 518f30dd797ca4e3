//! # bite-rtcl
//!
//! The robot team command language (RTCL) of Kaminka & Frenkel's second
//! paper, compiled to BITE behavior graphs. A mission is one command a
//! line:
//!
//! ```text
//! find::::yellow=>box     # look for a yellow object, call it `box`
//! move:box:-.5:.5         # push it to (-0.5, 0.5) from where the robots started
//! ```
//!
//! The compiler has the stages the paper names:
//!
//! 1. [`lex`]: text to tokens with spans ([`lexer`]);
//! 2. [`parse`]: tokens to a [`Mission`] syntax tree, recovering at line
//!    ends ([`parser`]);
//! 3. [`check`]: the commands against the command [`Library`]: arity,
//!    types, names defined before use ([`check`](mod@check));
//! 4. code generation: a behavior graph (YAML in the `bite-core` format),
//!    the motor schemas of its skills with per-command priorities, the
//!    beliefs its conditions read and the targets its results designate
//!    ([`codegen`]).
//!
//! The commands themselves are data: `commands.yaml`, the "precompiled
//! repertoire" ([`Library::builtin`]). The language and the library format
//! are described in `docs/rtcl.md`.
//!
//! ```
//! use bite_rtcl::{CompileOptions, Library, compile};
//! let out = compile(
//!     "search-rescue.rtcl",
//!     "find::::yellow=>box\nmove:box:-.5:.5\n",
//!     &Library::builtin(),
//!     &CompileOptions { origin: [6.7, 1.5], ..CompileOptions::default() },
//! )
//! .expect("compiles");
//! assert!(out.graph().contains("move_2_push"));
//! assert_eq!(out.beliefs["move_2_delivered"], "dist(box_pos, [6.2, 2]) < 0.3");
//! assert_eq!(out.targets["box"].colour.as_deref(), Some("yellow"));
//! ```

#![warn(missing_docs)]

pub mod ast;
pub mod check;
pub mod codegen;
pub mod lexer;
pub mod library;
pub mod parser;
pub mod source;
pub mod template;

pub use ast::{Command, Mission, Name, Param, ParamKind};
pub use check::Step;
pub use lexer::{Token, TokenKind, lex};
pub use library::Library;
pub use source::{SourceMap, Span};
pub use template::Json;

use bite_core::diag::{Diagnostic, Diagnostics, Loc};
use serde::Serialize;
use std::collections::BTreeMap;

/// Largest mission accepted, in bytes.
pub const MAX_SOURCE_BYTES: usize = bite_core::yaml::MAX_FILE_BYTES;

/// How to compile.
#[derive(Clone, Debug, PartialEq)]
pub struct CompileOptions {
    /// Where the mission's (0, 0) is in the world (metres): where the robots
    /// started. It is added to every coordinate the compiler writes into
    /// schemas and beliefs. Default `[0, 0]`.
    pub origin: [f64; 2],
    /// The size of the team the graph is written for (`team: { robots: N }`);
    /// commands that split the team per robot (`scan`, `formation`) make
    /// one child per robot. Default 2, the paper's team.
    pub robots: usize,
}

impl Default for CompileOptions {
    fn default() -> Self {
        CompileOptions {
            origin: [0.0, 0.0],
            robots: 2,
        }
    }
}

/// What a named result (`find::::yellow=>box`) designates: the object the
/// robots look for. The simulator gives every target `t` the percepts
/// `t_seen`, `t_pos`, `t_distance`, `t_bearing`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Target {
    /// Its colour, if given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub colour: Option<String>,
    /// Its length, width and height (m), where given; `None` when none is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub size: Option<[Option<f64>; 3]>,
}

/// Which behaviors a command became.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct StepInfo {
    /// Position in the mission, from 1.
    pub index: usize,
    /// Its line in the mission.
    pub line: u32,
    /// The command (`find`).
    pub command: String,
    /// Its behavior in the mission's chain (`find_1`).
    pub behavior: String,
    /// All the behaviors it decomposed into, its own first.
    pub behaviors: Vec<String>,
    /// The name of its result.
    pub result: Option<String>,
}

/// A compiled mission.
#[derive(Clone, Debug, PartialEq)]
pub struct Compiled {
    /// The behavior graph as data: loaded without writing and parsing YAML
    /// ([`Compiled::load_graph`]), written as YAML on demand
    /// ([`Compiled::graph`]).
    pub generated: codegen::GeneratedGraph,
    /// For every skill the graph uses: its motor schemas, in the scenario
    /// format (`{"schema": "wander", "speed": 0.25, "layer": 1}`), as the
    /// library's templates rendered them (their constant parts shared;
    /// [`Compiled::skills_json`] gives them as `serde_json` values).
    pub skills: BTreeMap<String, Vec<Json>>,
    /// Beliefs the graph's conditions read, as condition-language
    /// expressions over the physical world's percepts (to merge into the
    /// scenario's `physics.beliefs`).
    pub beliefs: BTreeMap<String, String>,
    /// What each named result designates.
    pub targets: BTreeMap<String, Target>,
    /// The commands, in order, and their behaviors.
    pub steps: Vec<StepInfo>,
    /// Warnings (the mission compiled anyway).
    pub warnings: Vec<Diagnostic>,
}

impl Compiled {
    /// The behavior graph, YAML in the `bite-core` format, with a header
    /// comment naming the mission file. Written when asked: running a
    /// mission does not need it ([`Compiled::load_graph`]).
    pub fn graph(&self) -> String {
        self.generated.yaml()
    }

    /// The compiled graph, validated as any graph is: the same
    /// [`BehaviorGraph`](bite_core::BehaviorGraph) (and warnings) as
    /// `bite_core::graph::load_str(file, &self.graph())`, without writing and
    /// parsing YAML. `file` names it in messages; its diagnostics have no
    /// line or column (`Loc::UNKNOWN`), the behaviors' names say where.
    pub fn load_graph(
        &self,
        file: &std::sync::Arc<str>,
    ) -> Result<bite_core::BehaviorGraph, Diagnostics> {
        bite_core::graph::load_parts(file, &self.generated.header(), &self.generated.behaviors())
    }

    /// [`Compiled::skills`] as `serde_json` values (what a scenario's
    /// mission parts take).
    pub fn skills_json(&self) -> BTreeMap<String, Vec<serde_json::Value>> {
        (self.skills.iter())
            .map(|(name, schemas)| (name.clone(), schemas.iter().map(Json::to_json).collect()))
            .collect()
    }

    /// The skills, beliefs and targets as a YAML fragment in the scenario
    /// format, to read or to merge into a physical-world scenario:
    ///
    /// ```yaml
    /// physics:
    ///   targets:
    ///     box: { colour: yellow }
    ///   beliefs:
    ///     find_1_found: "known(box_pos)"
    /// skills:
    ///   find_1:
    ///     schemas:
    ///       - { schema: wander, speed: 0.25, period: 3, layer: 1 }
    /// ```
    pub fn world_yaml(&self) -> String {
        use codegen::{flow, quote};
        use std::fmt::Write as _;
        let mut y = String::new();
        y.push_str("# Targets, beliefs and skills of the compiled mission (scenario format).\n");
        y.push_str("physics:\n");
        if self.targets.is_empty() {
            y.push_str("  targets: {}\n");
        } else {
            y.push_str("  targets:\n");
            for (name, t) in &self.targets {
                let v = serde_json::to_value(t).unwrap_or(serde_json::Value::Null);
                let _ = writeln!(y, "    {name}: {}", flow(&v));
            }
        }
        if self.beliefs.is_empty() {
            y.push_str("  beliefs: {}\n");
        } else {
            y.push_str("  beliefs:\n");
            for (name, cond) in &self.beliefs {
                let _ = writeln!(y, "    {name}: {}", quote(cond));
            }
        }
        y.push_str("skills:\n");
        for (name, schemas) in &self.skills {
            let _ = writeln!(y, "  {name}:\n    schemas:");
            for s in schemas {
                let _ = writeln!(y, "      - {}", flow(&s.to_json()));
            }
        }
        y
    }
}

/// Parse a mission: the commands that parsed, and a diagnostic for every
/// line that did not (see [`parser`]).
pub fn parse(file: &str, source: &str) -> (Mission, Vec<Diagnostic>) {
    parser::parse(file, source)
}

/// Check a parsed mission against a library: the steps of the commands
/// that checked, and every problem (see [`check`](mod@check)).
pub fn check(
    file: &str,
    source: &str,
    mission: &Mission,
    lib: &Library,
) -> (Vec<Step>, Vec<Diagnostic>) {
    check::check(&SourceMap::new(file, source), mission, lib)
}

/// Compile a mission: lex, parse, check, generate. `file` names the
/// mission in messages and in the graph's header. On failure, every
/// problem found, in the order of the file.
pub fn compile(
    file: &str,
    source: &str,
    lib: &Library,
    opts: &CompileOptions,
) -> Result<Compiled, Diagnostics> {
    let map = SourceMap::new(file, source);
    if source.len() > MAX_SOURCE_BYTES {
        return Err(Diagnostics(vec![Diagnostic::error(
            map.file(),
            Loc::UNKNOWN,
            "too-large",
            format!(
                "the mission is {} bytes; the limit is {MAX_SOURCE_BYTES}",
                source.len()
            ),
        )]));
    }
    if opts.robots == 0
        || opts.robots > bite_core::graph::MAX_ROBOTS
        || !opts
            .origin
            .iter()
            .all(|x| x.is_finite() && x.abs() <= check::MAX_NUMBER)
    {
        return Err(Diagnostics(vec![
            Diagnostic::error(
                map.file(),
                Loc::UNKNOWN,
                "bad-options",
                format!(
                    "cannot compile for {} robots with the origin at {:?}",
                    opts.robots, opts.origin
                ),
            )
            .with_hint(format!(
                "the team has 1 to {} robots; the origin's coordinates are at most {} in size",
                bite_core::graph::MAX_ROBOTS,
                check::MAX_NUMBER
            )),
        ]));
    }
    let tokens = lex(source);
    let (mission, mut diags) = parser::parse_tokens(&map, &tokens);
    let (steps, more) = check::check(&map, &mission, lib);
    diags.extend(more);
    if mission.commands.is_empty() && mission.recovered.is_empty() && diags.is_empty() {
        diags.push(
            Diagnostic::error(
                map.file(),
                Loc::new(1, 1),
                "empty-mission",
                "the mission has no commands",
            )
            .with_hint("write one command a line, e.g. `find::::yellow=>box`"),
        );
    }
    if diags.iter().any(Diagnostic::is_error) {
        diags.sort_by_key(|d| d.loc);
        return Err(Diagnostics(diags));
    }
    match codegen::generate(&map, &steps, lib, opts) {
        Ok(mut out) => {
            diags.append(&mut out.warnings);
            diags.sort_by_key(|d| d.loc);
            out.warnings = diags;
            Ok(out)
        }
        Err(mut errs) => {
            errs.extend(diags);
            errs.sort_by_key(|d| d.loc);
            Err(Diagnostics(errs))
        }
    }
}
