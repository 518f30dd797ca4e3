//! Pictures of a physical run: the arena, obstacles, objects and every
//! robot's trajectory coloured by the behavior it was running, with the
//! formation links (who keeps a slot on whom) drawn at regular moments.
//! Plain SVG, written by hand: it opens in any browser.

use super::{Sample, Shape, World};
use glam::DVec2;
use std::fmt::Write;

/// Colours for behaviors (Okabe-Ito, then a few more), readable on white
/// and by colour-blind readers.
pub const PALETTE: &[&str] = &[
    "#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442", "#000000",
    "#7F3C8D", "#11A579", "#3969AC", "#F2B701", "#E73F74", "#80BA5A",
];

/// Pixels per metre.
const SCALE: f64 = 80.0;
const MARGIN: f64 = 30.0;
const LEGEND: f64 = 190.0;

/// What the picture needs besides the world.
pub struct Labels<'a> {
    /// Title line.
    pub title: String,
    /// Robot names by index.
    pub robots: &'a [String],
    /// Behavior names by id.
    pub behaviors: &'a dyn Fn(bite_core::ids::BehaviorId) -> String,
    /// Draw the state at this time (`None`: the end of the run).
    pub at: Option<f64>,
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Draw the run (up to `labels.at`) as an SVG document.
pub fn draw(world: &World, labels: &Labels<'_>) -> String {
    let spec = world.spec();
    let (w, h) = (spec.arena.x, spec.arena.y);
    let width = w * SCALE + 2.0 * MARGIN + LEGEND;
    let height = h * SCALE + 2.0 * MARGIN + 30.0;
    let top = MARGIN + 30.0;
    let px = |p: DVec2| (MARGIN + p.x * SCALE, top + (h - p.y) * SCALE);
    let until = labels.at.unwrap_or(f64::INFINITY);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{MARGIN}" y="20" font-size="14" font-weight="bold">{}</text>"#,
        esc(&labels.title)
    );
    // Arena and a 1 m grid.
    let (ax, ay) = px(DVec2::new(0.0, h));
    let _ = writeln!(
        s,
        r##"<rect x="{ax:.1}" y="{ay:.1}" width="{:.1}" height="{:.1}" fill="#fafafa" stroke="#333" stroke-width="3"/>"##,
        w * SCALE,
        h * SCALE
    );
    for gx in 1..w.ceil() as i64 {
        let (x0, y0) = px(DVec2::new(gx as f64, 0.0));
        let (_, y1) = px(DVec2::new(gx as f64, h));
        let _ = writeln!(
            s,
            r##"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x0:.1}" y2="{y1:.1}" stroke="#e4e4e4"/>"##
        );
    }
    for gy in 1..h.ceil() as i64 {
        let (x0, y0) = px(DVec2::new(0.0, gy as f64));
        let (x1, _) = px(DVec2::new(w, gy as f64));
        let _ = writeln!(
            s,
            r##"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y0:.1}" stroke="#e4e4e4"/>"##
        );
    }
    // Zones.
    for (name, [x0, y0, x1, y1]) in &spec.zones {
        let (zx, zy) = px(DVec2::new(x0.min(*x1), y0.max(*y1)));
        let _ = writeln!(
            s,
            r##"<rect x="{zx:.1}" y="{zy:.1}" width="{:.1}" height="{:.1}" fill="#2ca02c" fill-opacity="0.12" stroke="#2ca02c" stroke-dasharray="6 4"/><text x="{:.1}" y="{:.1}" fill="#2ca02c">{}</text>"##,
            (x1 - x0).abs() * SCALE,
            (y1 - y0).abs() * SCALE,
            zx + 4.0,
            zy + 14.0,
            esc(name)
        );
    }
    let shape = |s: &mut String, at: DVec2, angle: f64, sh: &Shape, style: &str| match sh {
        Shape::Disc(r) => {
            let (cx, cy) = px(at);
            let _ = writeln!(
                s,
                r#"<circle cx="{cx:.1}" cy="{cy:.1}" r="{:.1}" {style}/>"#,
                r * SCALE
            );
        }
        Shape::Box(size) => {
            let (cx, cy) = px(at);
            let _ = writeln!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" transform="rotate({:.1} {cx:.1} {cy:.1})" {style}/>"#,
                cx - size.x * SCALE / 2.0,
                cy - size.y * SCALE / 2.0,
                size.x * SCALE,
                size.y * SCALE,
                -angle.to_degrees()
            );
        }
    };
    for o in &spec.obstacles {
        shape(
            &mut s,
            o.at,
            o.angle,
            &o.shape,
            r##"fill="#888" stroke="#444""##,
        );
    }
    // Objects: where they started (dashed), their path, where they are.
    for (k, o) in spec.objects.iter().enumerate() {
        let colour = o.colour.as_deref().unwrap_or("#999");
        shape(
            &mut s,
            o.at,
            o.angle,
            &o.shape,
            &format!(r#"fill="none" stroke="{colour}" stroke-dasharray="4 3""#),
        );
        let trail: Vec<&(f64, DVec2)> = world.object_trails()[k]
            .iter()
            .filter(|(t, _)| *t <= until)
            .collect();
        if trail.len() > 1 {
            let pts: Vec<String> = trail
                .iter()
                .map(|(_, p)| {
                    let (x, y) = px(*p);
                    format!("{x:.1},{y:.1}")
                })
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2" stroke-dasharray="2 3"/>"#,
                pts.join(" ")
            );
        }
        let at = trail.last().map_or(o.at, |(_, p)| *p);
        shape(
            &mut s,
            at,
            o.angle,
            &o.shape,
            &format!(r##"fill="{colour}" fill-opacity="0.85" stroke="#333""##),
        );
        if let Some(n) = &o.name {
            let (x, y) = px(at);
            let _ = writeln!(
                s,
                r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle" font-size="11">{}</text>"#,
                y + o.shape.reach() * SCALE + 12.0,
                esc(n)
            );
        }
    }
    // Behavior colours, in order of first appearance.
    let trails: Vec<Vec<Sample>> = world
        .trails()
        .map(|t| t.iter().filter(|x| x.t <= until).copied().collect())
        .collect();
    let mut behaviors: Vec<bite_core::ids::BehaviorId> = Vec::new();
    for t in &trails {
        for x in t {
            if let Some(b) = x.behavior
                && !behaviors.contains(&b)
            {
                behaviors.push(b);
            }
        }
    }
    behaviors.sort();
    let colour_of = |b: Option<bite_core::ids::BehaviorId>| match b {
        None => "#bbbbbb",
        Some(b) => behaviors
            .iter()
            .position(|x| *x == b)
            .map_or("#bbbbbb", |i| PALETTE[i % PALETTE.len()]),
    };
    // Formation links at ten moments of the run.
    let end = trails
        .iter()
        .filter_map(|t| t.last().map(|x| x.t))
        .fold(0.0, f64::max);
    for k in 1..=10 {
        let at = end * k as f64 / 10.0;
        for t in &trails {
            let Some(x) = t.iter().rev().find(|x| x.t <= at) else {
                continue;
            };
            if let Some(l) = x.link
                && let Some(y) = trails
                    .get(l as usize)
                    .and_then(|lt| lt.iter().rev().find(|y| y.t <= at))
            {
                let (x0, y0) = px(x.pos);
                let (x1, y1) = px(y.pos);
                let _ = writeln!(
                    s,
                    r##"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="#555" stroke-width="1" stroke-dasharray="3 3" opacity="0.7"/>"##
                );
            }
        }
    }
    // Trajectories, one polyline per stretch of one behavior.
    for t in &trails {
        let mut i = 0;
        while i < t.len() {
            let b = t[i].behavior;
            let mut j = i;
            while j + 1 < t.len() && t[j + 1].behavior == b {
                j += 1;
            }
            // Join to the next stretch so the line is continuous.
            let last = (j + 1).min(t.len() - 1);
            let pts: Vec<String> = t[i..=last]
                .iter()
                .map(|x| {
                    let (a, b) = px(x.pos);
                    format!("{a:.1},{b:.1}")
                })
                .collect();
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="3" stroke-linecap="round" stroke-linejoin="round"/>"#,
                pts.join(" "),
                colour_of(b)
            );
            i = j + 1;
        }
    }
    // Robots: start (hollow), now (filled, heading tick, name).
    let radius = spec.robot.radius;
    for (i, t) in trails.iter().enumerate() {
        let name = labels.robots.get(i).map_or("?", String::as_str);
        if let Some(first) = t.first() {
            let (x, y) = px(first.pos);
            let _ = writeln!(
                s,
                r##"<circle cx="{x:.1}" cy="{y:.1}" r="{:.1}" fill="white" stroke="#333" stroke-dasharray="2 2"/>"##,
                radius * SCALE
            );
        }
        if let Some(last) = t.last() {
            let (x, y) = px(last.pos);
            let (hx, hy) = px(last.pos + DVec2::from_angle(last.heading) * radius * 1.6);
            let _ = writeln!(
                s,
                r##"<circle cx="{x:.1}" cy="{y:.1}" r="{:.1}" fill="{}" stroke="#111" stroke-width="2"/><line x1="{x:.1}" y1="{y:.1}" x2="{hx:.1}" y2="{hy:.1}" stroke="#111" stroke-width="2.5"/><text x="{:.1}" y="{:.1}" font-weight="bold">{}</text>"##,
                radius * SCALE,
                colour_of(last.behavior),
                x + radius * SCALE + 3.0,
                y - radius * SCALE - 2.0,
                esc(name)
            );
        }
    }
    // Legend.
    let lx = MARGIN + w * SCALE + 20.0;
    let mut ly = top + 10.0;
    let _ = writeln!(
        s,
        r#"<text x="{lx:.1}" y="{ly:.1}" font-weight="bold">behavior</text>"#
    );
    for b in &behaviors {
        ly += 18.0;
        let _ = writeln!(
            s,
            r#"<line x1="{lx:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{}" stroke-width="4"/><text x="{:.1}" y="{ly:.1}">{}</text>"#,
            ly - 4.0,
            lx + 24.0,
            ly - 4.0,
            colour_of(Some(*b)),
            lx + 30.0,
            esc(&(labels.behaviors)(*b))
        );
    }
    ly += 26.0;
    let _ = writeln!(
        s,
        r##"<line x1="{lx:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#555" stroke-dasharray="3 3"/><text x="{:.1}" y="{ly:.1}">formation link</text>"##,
        ly - 4.0,
        lx + 24.0,
        ly - 4.0,
        lx + 30.0
    );
    let _ = writeln!(s, "</svg>");
    s
}
