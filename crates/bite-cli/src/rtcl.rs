//! Missions in the robot team command language (`.rtcl`): compiled into a
//! behavior graph and the world parts (skills, beliefs, targets) that a
//! physical-world scenario takes.

use anyhow::Result;
use bite_agent::spec::TargetSpec;
use bite_core::graph::BehaviorGraph;
use bite_rtcl::{CompileOptions, Compiled, Library};
use bite_sim::{MissionParts, Scenario};
use std::path::Path;
use std::sync::Arc;

use crate::{bad_input, print_diags};

/// Is this file a mission in the command language?
pub fn is_mission(p: &Path) -> bool {
    p.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("rtcl"))
}

/// The command library: the given file, or the built-in one.
pub fn library(path: Option<&Path>) -> Result<Library> {
    match path {
        Some(p) => Library::load(p).map_err(bad_input),
        None => Ok(Library::builtin()),
    }
}

/// Compile a mission file.
pub fn compile(path: &Path, lib: &Library, opts: &CompileOptions) -> Result<Compiled> {
    // Read as every user file is: bounded, and UTF-8 located.
    let (file, source) = bite_core::yaml::read_file(path).map_err(bad_input)?;
    let compiled = bite_rtcl::compile(&file, &source, lib, opts).map_err(bad_input)?;
    print_diags(&compiled.warnings);
    Ok(compiled)
}

/// The compiled graph, validated as any graph file is; handed over as
/// data, not parsed back from its YAML (`Compiled::load_graph`: the same
/// graph, its diagnostics without line and column).
pub fn graph(path: &Path, compiled: &Compiled) -> Result<BehaviorGraph> {
    let name: Arc<str> = Arc::from(format!("{} (compiled)", path.display()));
    let g = compiled.load_graph(&name).map_err(bad_input)?;
    print_diags(g.warnings());
    Ok(g)
}

/// The compile options a scenario implies: the team's start as the
/// mission's (0, 0) and the team size, unless given.
pub fn options_for(scenario: &Scenario, robots: Option<usize>) -> CompileOptions {
    let d = CompileOptions::default();
    let placed = scenario.physics.as_ref().map_or(0, |p| p.start.len());
    CompileOptions {
        origin: scenario
            .physics
            .as_ref()
            .map_or(d.origin, |p| p.mission_origin().to_array()),
        robots: robots
            .or(scenario.robots)
            .or((placed > 0).then_some(placed))
            .unwrap_or(d.robots),
    }
}

/// The scenario with the mission's skills, beliefs and targets added.
pub fn bind(path: &Path, compiled: &Compiled, scenario: &Scenario) -> Result<Scenario> {
    bind_parts(&path.display().to_string(), compiled, scenario).map_err(bad_input)
}

/// [`bind`] for a mission that is not a file (`label` names it in errors).
pub fn bind_parts(
    label: &str,
    compiled: &Compiled,
    scenario: &Scenario,
) -> Result<Scenario, bite_core::diag::Diagnostics> {
    let parts = MissionParts {
        file: Arc::from(label),
        skills: compiled.skills_json(),
        beliefs: compiled.beliefs.clone(),
        targets: (compiled.targets.iter())
            .map(|(k, t)| {
                (
                    k.clone(),
                    TargetSpec {
                        colour: t.colour.clone(),
                        size: t.size.unwrap_or([None; 3]),
                    },
                )
            })
            .collect(),
    };
    scenario.with_mission(&parts)
}
