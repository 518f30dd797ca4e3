//! Graphviz output of a behavior graph.
//!
//! Decomposition edges (`children`) are dashed grey arrows with hollow heads;
//! sequential edges (`next`) are solid blue arrows. Team behaviors have a
//! double border; the start behavior is bold. Every coordination point is
//! listed in its behavior's box with the protocol bound to it.

use super::BehaviorGraph;
use crate::ids::BehaviorId;
use crate::ids::Kind;
use std::fmt::Write;

/// DOT text, with each point's protocol given by the graph's own bindings.
pub fn to_dot(g: &BehaviorGraph) -> String {
    to_dot_with(g, &|b, kind| {
        g.own_binding(b, kind)
            .and_then(|x| x.protocol.clone())
            .or_else(|| g.default_binding(kind).and_then(|x| x.protocol.clone()))
            .unwrap_or_else(|| "default".to_string())
    })
}

fn esc(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}

/// DOT text; `protocol(b, kind)` names the protocol bound at each point.
pub fn to_dot_with(g: &BehaviorGraph, protocol: &dyn Fn(BehaviorId, Kind) -> String) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "digraph \"{}\" {{", esc(g.name()));
    let _ = writeln!(s, "  rankdir=TB; newrank=true; fontname=\"Helvetica\";");
    let _ = writeln!(
        s,
        "  label=\"{}\\n(dashed: decomposition, solid: sequence; double border: team behavior)\"; labelloc=t;",
        esc(&g.to_string())
    );
    let _ = writeln!(
        s,
        "  node [shape=box, style=\"rounded,filled\", fillcolor=\"#ffffff\", fontname=\"Helvetica\", fontsize=11];"
    );
    let _ = writeln!(s, "  edge [fontname=\"Helvetica\", fontsize=9];");
    for b in g.behaviors() {
        let mut label = esc(&b.name);
        if let Some(sk) = &b.skill {
            let _ = write!(label, "\\nskill: {}", esc(&sk.name));
        }
        if let Some(u) = &b.until {
            let _ = write!(label, "\\nuntil: {}", esc(u.source()));
        }
        if let Some(u) = &b.urgent {
            let _ = write!(label, "\\nurgent: {}", esc(u.source()));
        }
        let mut fill = "#ffffff";
        for kind in Kind::ALL {
            if g.is_point(b.id, kind) {
                let mark = match kind {
                    Kind::Sync => "◆ sync",
                    Kind::Allocate => "▲ alloc",
                    Kind::Terminate => "■ term",
                };
                let _ = write!(
                    label,
                    "\\n{mark} {}: {}",
                    esc(&g.point_name(b.id, kind)),
                    esc(&protocol(b.id, kind))
                );
                if kind != Kind::Terminate {
                    fill = if kind == Kind::Allocate {
                        "#fff4d6"
                    } else {
                        "#e6f0ff"
                    };
                }
            }
        }
        let mut attrs = format!("label=\"{label}\", fillcolor=\"{fill}\"");
        if b.team {
            attrs.push_str(", peripheries=2");
        }
        if b.id == g.start() {
            attrs.push_str(", penwidth=2.5");
        }
        let _ = writeln!(s, "  b{} [{attrs}];", b.id.0);
    }
    for b in g.behaviors() {
        for c in &b.children {
            let _ = writeln!(
                s,
                "  b{} -> b{} [style=dashed, color=\"#777777\", arrowhead=onormal];",
                b.id.0, c.0
            );
        }
        for n in &b.next {
            let _ = writeln!(
                s,
                "  b{} -> b{} [color=\"#1f5fbf\", penwidth=1.6, constraint={}];",
                b.id.0,
                n.0,
                // Back edges of sequential cycles should not distort ranks.
                if n.0 <= b.id.0 { "false" } else { "true" }
            );
        }
    }
    s.push_str("}\n");
    s
}
