//! What the editor's text is: its diagnostics from the project's own
//! compiler and checker, the behavior graph drawn with the protocols bound
//! at its points, and the team it gives to run (the same path `bite run`
//! takes, from text instead of a file).

use bite_core::diag::{Diagnostic, Diagnostics, Loc};
use bite_core::graph::BehaviorGraph;
use bite_core::mission::Mission;
use bite_sim::Scenario;
use serde_json::{Value as J, json};
use std::sync::Arc;

/// What the editor holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// A mission in the robot team command language.
    Rtcl,
    /// A behavior graph (YAML).
    Yaml,
}

/// The text, understood.
pub struct Analysis {
    /// Every finding, errors and warnings, in file order.
    pub diagnostics: Vec<Diagnostic>,
    /// The mission, ready to run (no errors).
    pub mission: Option<(Arc<Mission>, Scenario)>,
}

fn diags(d: Diagnostics) -> Vec<Diagnostic> {
    d.0
}

/// Compile or load `text` (named `file` in messages) against `scenario`.
pub fn analyze(
    kind: Kind,
    file: &str,
    text: &str,
    lib: &bite_rtcl::Library,
    scenario: &Scenario,
    robots: Option<usize>,
    registry: &bite_core::interaction::Registry,
) -> Analysis {
    let mut out = Vec::new();
    let team: Result<(BehaviorGraph, Scenario), Vec<Diagnostic>> = match kind {
        Kind::Rtcl => {
            let opts = crate::rtcl::options_for(scenario, robots);
            match bite_rtcl::compile(file, text, lib, &opts) {
                Err(d) => Err(diags(d)),
                Ok(compiled) => {
                    out.extend(compiled.warnings.iter().cloned());
                    let name: Arc<str> = Arc::from(format!("{file} (compiled)"));
                    bite_core::graph::load_str(&name, &compiled.graph())
                        .map_err(diags)
                        .and_then(|g| {
                            out.extend(g.warnings().iter().cloned());
                            crate::rtcl::bind_parts(file, &compiled, scenario)
                                .map(|s| (g, s))
                                .map_err(diags)
                        })
                }
            }
        }
        Kind::Yaml => {
            let name: Arc<str> = Arc::from(file);
            bite_core::graph::load_str(&name, text)
                .map(|g| {
                    out.extend(g.warnings().iter().cloned());
                    (g, scenario.clone())
                })
                .map_err(diags)
        }
    };
    let mission = match team {
        Err(d) => {
            out.extend(d);
            None
        }
        Ok((g, s)) => match bite_sim::runner::prepare(&g, &s, robots, registry) {
            Ok(m) => Some((m, s)),
            Err(d) => {
                out.extend(diags(d));
                None
            }
        },
    };
    out.sort_by_key(|d| {
        (
            d.loc.line == 0,
            d.loc,
            d.severity != bite_core::diag::Severity::Error,
        )
    });
    Analysis {
        diagnostics: out,
        mission,
    }
}

/// A diagnostic for the page: where (1-based; 0 when unknown), what, how
/// to fix it.
pub fn diagnostic_json(d: &Diagnostic) -> J {
    let Loc { line, col } = d.loc;
    json!({
        "severity": if d.is_error() { "error" } else { "warning" },
        "file": &*d.file,
        "line": line,
        "col": col,
        "code": d.code,
        "message": d.message,
        "hint": d.hint,
        "detail": d.detail,
        "text": d.to_string(),
    })
}

/// The graph drawn (SVG) with its points and their bound protocols.
pub fn graph_json(m: &Mission) -> J {
    let g = m.graph();
    let protocol = |b, k| {
        m.bound(b, k)
            .map_or("?".into(), |x| x.protocol.name().to_string())
    };
    let points: Vec<J> = g
        .points()
        .iter()
        .map(|p| {
            json!({
                "name": p.name,
                "kind": p.kind.to_string(),
                "behavior": g.name_of(p.behavior),
                "protocol": protocol(p.behavior, p.kind),
            })
        })
        .collect();
    json!({
        "name": g.name(),
        "behaviors": g.len(),
        "robots": g.roster().len(),
        "svg": bite_core::graph::svg::to_svg_with(g, &protocol),
        "points": points,
    })
}
