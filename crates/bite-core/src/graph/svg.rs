//! A behavior graph drawn as SVG, without Graphviz: the decomposition tree
//! top-down (a behavior above its children, dashed grey edges), execution
//! chains left to right in each level (solid blue sequential edges), every
//! coordination point listed in its behavior's box with its protocol, as
//! [`dot`](super::dot) draws them.
//!
//! The layout is a tidy tree: each behavior sits centred over the children
//! it was first reached from, subtrees side by side in file order. A
//! behavior reached from several parents is drawn once, under the first;
//! the other decomposition edges are drawn to it where it is. Each box is
//! a `<g class="behavior" data-behavior="NAME">`, so a page can mark the
//! behaviors a team is running.

use super::BehaviorGraph;
use crate::ids::{BehaviorId, Kind};
use std::fmt::Write;

const CHAR_W: f64 = 6.6;
const LINE_H: f64 = 14.0;
const PAD: f64 = 8.0;
const GAP_X: f64 = 18.0;
const GAP_Y: f64 = 46.0;
const MARGIN: f64 = 12.0;

struct Node {
    lines: Vec<(String, &'static str)>,
    w: f64,
    h: f64,
    x: f64,
    depth: usize,
    fill: &'static str,
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// SVG text; `protocol(b, kind)` names the protocol bound at each point.
pub fn to_svg_with(g: &BehaviorGraph, protocol: &dyn Fn(BehaviorId, Kind) -> String) -> String {
    let n = g.len();
    let mut nodes: Vec<Node> = g
        .behaviors()
        .iter()
        .map(|b| {
            let mut lines = vec![(b.name.clone(), "name")];
            if let Some(sk) = &b.skill {
                lines.push((format!("skill: {}", sk.name), "detail"));
            }
            if let Some(u) = &b.until {
                let mut s = u.source().to_string();
                if s.chars().count() > 40 {
                    s = s.chars().take(39).collect::<String>() + "…";
                }
                lines.push((format!("until: {s}"), "detail"));
            }
            let mut fill = "#ffffff";
            for kind in Kind::ALL {
                if g.is_point(b.id, kind) {
                    let (mark, class) = match kind {
                        Kind::Sync => ("◆ sync", "sync"),
                        Kind::Allocate => ("▲ alloc", "alloc"),
                        Kind::Terminate => ("■ term", "term"),
                    };
                    lines.push((format!("{mark}: {}", protocol(b.id, kind)), class));
                    if kind != Kind::Terminate {
                        fill = if kind == Kind::Allocate {
                            "#fff4d6"
                        } else {
                            "#e6f0ff"
                        };
                    }
                }
            }
            let chars = lines
                .iter()
                .map(|(l, _)| l.chars().count())
                .max()
                .unwrap_or(1);
            Node {
                w: chars as f64 * CHAR_W + 2.0 * PAD,
                h: lines.len() as f64 * LINE_H + PAD,
                lines,
                x: 0.0,
                depth: 0,
                fill,
            }
        })
        .collect();
    // The tree: each behavior under the first parent that names it.
    let mut parent: Vec<Option<usize>> = vec![None; n];
    // A chain's later behaviors (reached by sequential edges from a child)
    // belong to the same parent.
    for b in g.behaviors() {
        let p = b.id.0 as usize;
        let mut work: Vec<usize> = b.children.iter().map(|c| c.0 as usize).collect();
        while let Some(c) = work.pop() {
            if parent[c].is_some() || c == p || c == g.start().0 as usize {
                continue;
            }
            parent[c] = Some(p);
            work.extend(g.behaviors()[c].next.iter().map(|x| x.0 as usize));
        }
    }
    // Break cycles of first parents (a malformed graph is refused earlier,
    // but drawing must never loop): walk up at most n steps.
    for i in 0..n {
        let mut at = parent[i];
        let mut steps = 0;
        while let Some(p) = at {
            steps += 1;
            if p == i || steps > n {
                parent[i] = None;
                break;
            }
            at = parent[p];
        }
    }
    let mut kids: Vec<Vec<usize>> = vec![Vec::new(); n];
    for b in g.behaviors() {
        let p = b.id.0 as usize;
        for c in &b.children {
            let c = c.0 as usize;
            if parent[c] == Some(p) && !kids[p].contains(&c) {
                kids[p].push(c);
            }
        }
    }
    for (i, p) in parent.iter().enumerate() {
        if let Some(p) = *p
            && !kids[p].contains(&i)
        {
            kids[p].push(i);
        }
    }
    // Siblings in execution order: a chain's head first, then what follows.
    for list in kids.iter_mut() {
        let mut ordered: Vec<usize> = Vec::with_capacity(list.len());
        let heads = list.clone();
        for h in heads {
            let mut at = Some(h);
            while let Some(i) = at {
                if ordered.contains(&i) || !list.contains(&i) {
                    break;
                }
                ordered.push(i);
                at = g.behaviors()[i].next.first().map(|x| x.0 as usize);
            }
        }
        for i in list.iter() {
            if !ordered.contains(i) {
                ordered.push(*i);
            }
        }
        *list = ordered;
    }
    // Roots: the start behavior's chain first, then the others in id order.
    let mut roots: Vec<usize> = Vec::new();
    let mut at = Some(g.start().0 as usize);
    while let Some(i) = at {
        if roots.contains(&i) || parent[i].is_some() {
            break;
        }
        roots.push(i);
        at = g.behaviors()[i].next.first().map(|x| x.0 as usize);
    }
    for (i, p) in parent.iter().enumerate() {
        if p.is_none() && !roots.contains(&i) {
            roots.push(i);
        }
    }
    // Tidy layout, iteratively (graphs can be deep).
    fn width(i: usize, nodes: &[Node], kids: &[Vec<usize>], memo: &mut [f64]) -> f64 {
        let mut stack = vec![(i, false)];
        while let Some((j, done)) = stack.pop() {
            if done {
                let sum: f64 = kids[j].iter().map(|&c| memo[c]).sum::<f64>()
                    + GAP_X * kids[j].len().saturating_sub(1) as f64;
                memo[j] = nodes[j].w.max(sum);
            } else {
                stack.push((j, true));
                for &c in &kids[j] {
                    stack.push((c, false));
                }
            }
        }
        memo[i]
    }
    let mut memo = vec![0.0; n];
    let mut x0 = MARGIN;
    let mut place: Vec<(usize, f64, usize)> = Vec::new();
    for &r in &roots {
        let w = width(r, &nodes, &kids, &mut memo);
        place.push((r, x0, 0));
        x0 += w + GAP_X * 2.0;
    }
    while let Some((i, left, depth)) = place.pop() {
        let w = memo[i];
        nodes[i].x = left + w / 2.0;
        nodes[i].depth = depth;
        let sum: f64 = kids[i].iter().map(|&c| memo[c]).sum::<f64>()
            + GAP_X * kids[i].len().saturating_sub(1) as f64;
        let mut cx = left + (w - sum) / 2.0;
        for &c in &kids[i] {
            place.push((c, cx, depth + 1));
            cx += memo[c] + GAP_X;
        }
    }
    let depths = nodes.iter().map(|nd| nd.depth).max().map_or(0, |d| d + 1);
    let mut row_h = vec![0.0f64; depths];
    for nd in &nodes {
        row_h[nd.depth] = row_h[nd.depth].max(nd.h);
    }
    let mut row_y = vec![MARGIN + 18.0; depths];
    for d in 1..depths {
        row_y[d] = row_y[d - 1] + row_h[d - 1] + GAP_Y;
    }
    let total_w = (x0 - GAP_X * 2.0 + MARGIN).max(120.0);
    let total_h =
        row_y.last().copied().unwrap_or(MARGIN) + row_h.last().copied().unwrap_or(0.0) + MARGIN;
    let top = |i: usize| row_y[nodes[i].depth];
    let bottom = |i: usize| row_y[nodes[i].depth] + nodes[i].h;

    let mut s = String::new();
    let _ = writeln!(
        s,
        r##"<svg xmlns="http://www.w3.org/2000/svg" class="behavior-graph" width="{total_w:.0}" height="{total_h:.0}" viewBox="0 0 {total_w:.0} {total_h:.0}" font-family="Helvetica, Arial, sans-serif" font-size="11">"##
    );
    s.push_str(r##"<defs><marker id="seq" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" orient="auto"><path d="M0,0 L10,5 L0,10 z" fill="#1f5fbf"/></marker><marker id="dec" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" orient="auto"><path d="M0,0 L10,5 L0,10" fill="none" stroke="#777"/></marker></defs>"##);
    let _ = writeln!(
        s,
        r##"<text x="{MARGIN}" y="{}" font-size="12" font-weight="bold">{}</text>"##,
        MARGIN + 4.0,
        esc(&g.to_string())
    );
    // Decomposition edges.
    for b in g.behaviors() {
        let p = b.id.0 as usize;
        for c in &b.children {
            let c = c.0 as usize;
            let (x1, y1, x2, y2) = (nodes[p].x, bottom(p), nodes[c].x, top(c));
            let _ = writeln!(
                s,
                r##"<path class="decomposition" d="M{x1:.1},{y1:.1} C{x1:.1},{:.1} {x2:.1},{:.1} {x2:.1},{y2:.1}" fill="none" stroke="#777" stroke-dasharray="4 3" marker-end="url(#dec)"/>"##,
                y1 + GAP_Y / 2.0,
                y2 - GAP_Y / 2.0
            );
        }
    }
    // Sequential edges: straight between neighbours of one row, arcs
    // above otherwise (back edges of loops included).
    for b in g.behaviors() {
        let a = b.id.0 as usize;
        for nx in &b.next {
            let c = nx.0 as usize;
            let same_row = nodes[a].depth == nodes[c].depth;
            let d = if same_row && nodes[c].x > nodes[a].x {
                let y = top(a) + nodes[a].h.min(nodes[c].h) / 2.0;
                format!(
                    "M{:.1},{y:.1} L{:.1},{y:.1}",
                    nodes[a].x + nodes[a].w / 2.0,
                    nodes[c].x - nodes[c].w / 2.0
                )
            } else {
                let (x1, y1, x2, y2) = (nodes[a].x, top(a), nodes[c].x, top(c));
                let lift = 20.0 + (x1 - x2).abs() * 0.08;
                format!(
                    "M{x1:.1},{y1:.1} C{x1:.1},{:.1} {x2:.1},{:.1} {x2:.1},{y2:.1}",
                    y1 - lift,
                    y2 - lift
                )
            };
            let _ = writeln!(
                s,
                r##"<path class="sequence" d="{d}" fill="none" stroke="#1f5fbf" stroke-width="1.6" marker-end="url(#seq)"/>"##
            );
        }
    }
    for (i, b) in g.behaviors().iter().enumerate() {
        let nd = &nodes[i];
        let (x, y) = (nd.x - nd.w / 2.0, top(i));
        let stroke_w = if b.id == g.start() { 2.5 } else { 1.0 };
        let _ = write!(
            s,
            r##"<g class="behavior" data-behavior="{}"><rect x="{x:.1}" y="{y:.1}" width="{:.1}" height="{:.1}" rx="6" fill="{}" stroke="#333" stroke-width="{stroke_w}"/>"##,
            esc(&b.name),
            nd.w,
            nd.h,
            nd.fill
        );
        if b.team {
            let _ = write!(
                s,
                r##"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" rx="4" fill="none" stroke="#333" stroke-width="0.7"/>"##,
                x + 2.5,
                y + 2.5,
                nd.w - 5.0,
                nd.h - 5.0
            );
        }
        for (k, (line, class)) in nd.lines.iter().enumerate() {
            let weight = if *class == "name" {
                " font-weight=\"bold\""
            } else {
                ""
            };
            let colour = match *class {
                "sync" => "#1f5fbf",
                "alloc" => "#a05a00",
                "term" => "#7a1f1f",
                "detail" => "#555",
                _ => "#111",
            };
            let _ = write!(
                s,
                r##"<text class="{class}" x="{:.1}" y="{:.1}" text-anchor="middle" fill="{colour}"{weight}>{}</text>"##,
                nd.x,
                y + PAD / 2.0 + LINE_H * (k as f64 + 1.0) - 3.0,
                esc(line)
            );
        }
        s.push_str("</g>\n");
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    const G: &str = include_str!("../../../../examples/formation.yaml");

    #[test]
    fn every_behavior_is_a_box_with_its_points_and_edges() {
        let name: Arc<str> = Arc::from("g.yaml");
        let g = crate::graph::load_str(&name, G).expect("graph loads");
        let svg = to_svg_with(&g, &|_, k| format!("p-{k}"));
        for b in ["formation", "triangle", "line", "search", "walk", "lead"] {
            assert!(
                svg.contains(&format!("data-behavior=\"{b}\"")),
                "{b} missing:\n{svg}"
            );
        }
        let edges =
            |f: fn(&crate::graph::Behavior) -> usize| g.behaviors().iter().map(f).sum::<usize>();
        assert_eq!(
            svg.matches("class=\"decomposition\"").count(),
            edges(|b| b.children.len())
        );
        assert_eq!(
            svg.matches("class=\"sequence\"").count(),
            edges(|b| b.next.len())
        );
        assert!(svg.contains("▲ alloc: p-"), "{svg}");
        assert!(svg.contains("◆ sync: p-"), "{svg}");
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        // Parsable XML: every element closed.
        assert_eq!(svg.matches("<g ").count(), svg.matches("</g>").count());
    }

    #[test]
    fn children_sit_below_their_parent_and_chains_left_to_right() {
        let name: Arc<str> = Arc::from("g.yaml");
        let g = crate::graph::load_str(&name, G).expect("graph loads");
        let svg = to_svg_with(&g, &|_, _| "x".into());
        let pos = |b: &str| {
            let at = svg.find(&format!("data-behavior=\"{b}\"")).expect("box");
            let rest = &svg[at..];
            let num = |key: &str| -> f64 {
                let k = rest.find(key).expect("attr") + key.len();
                let end = rest[k..].find('"').expect("quote");
                rest[k..k + end].parse().expect("number")
            };
            (num("x=\""), num("y=\""))
        };
        assert!(pos("triangle").1 > pos("formation").1);
        assert!(pos("search").1 > pos("triangle").1);
        assert!(
            pos("line").0 > pos("triangle").0,
            "a chain runs left to right"
        );
        assert_eq!(pos("line").1, pos("triangle").1);
        assert!(pos("walk").0 > pos("search").0);
    }
}
