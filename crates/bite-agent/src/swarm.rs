//! Generated missions for large teams: the coverage task at any team
//! size, its robots starting in their cells or across the arena from
//! them, for `bite bench sim` and for tests.

/// The coverage mission at scale: `n` robots split a square arena of about
/// 16 m² per robot (pillars every 8 m, mid-lane, away from the lanes' ends)
/// into near-square cells, one each
/// (`scan` with `split`: the cell is the robot's rank in the team), and
/// sweep them. Robots start in their cells, where their sweep begins; the run stops after `seconds`
/// (a cell takes longer than a minute to sweep, so the figure is the
/// steady state of sensing, kernels, fusion and physics).
pub fn coverage_mission(n: usize, seconds: f64) -> (String, String) {
    cells_mission("coverage", n, seconds, |r| r, None)
}

/// The coverage mission with every robot (of `n` ≥ 2) starting in another's
/// cell, about half the arena away from its own on both axes (robot `r`
/// starts where robot [`crossing_start_cell`] starts in
/// [`coverage_mission`]): the team crosses the arena diagonally before it
/// sweeps, the bodies mixing as they pass each other. What a world costs
/// when its bodies move far from where they began (rapier's broad phase
/// keeps a tree of them: docs/performance.md, "The physical world,
/// 2026-12-02, evening").
pub fn crossing_mission(n: usize, seconds: f64) -> (String, String) {
    // Nothing is decided until the whole team has crossed and swept: the
    // run is not stalled until a robot could have crossed the whole arena
    // and swept its cell, and then some. Nor does the team's barrier give
    // up on a robot still at work before then: robots cross different
    // distances (some a few cells, some most of the arena), so they finish
    // minutes apart, and `term.wait-all`'s 30 s released the barrier under
    // the last ones (fault-free runs completed with timeouts: 7 seeds of 8
    // at 100 robots).
    let patience = ((side_of(n) + CELL_AREA / SPACING) / SPEED).ceil() + 120.0;
    cells_mission(
        "crossing",
        n,
        seconds,
        |r| crossing_start_cell(n, r),
        Some(patience),
    )
}

/// The cell robot `r` of `n` starts in, in [`crossing_mission`]: `r`
/// shifted by half the cells (half the rows up: the cells are numbered row
/// by row) and half a row more (half the row across), round the end. For
/// `n` ≥ 2 the shift is between 1 and `n` − 1: no robot starts at home.
pub fn crossing_start_cell(n: usize, r: usize) -> usize {
    (r + n / 2 + n.isqrt() / 2) % n.max(1)
}

/// Where the sweep of cell `cell` of `n` begins, and where a robot
/// starting in that cell is placed.
pub fn cell_start(n: usize, cell: usize) -> [f64; 2] {
    let side = side_of(n);
    let c = crate::schema::split_cell([0.0, 0.0, side, side], cell as u32, n as u32);
    // Where its sweep begins: by the cell's lower-left corner (pillars
    // stand mid-cell).
    [
        c[0] + 0.5_f64.min((c[2] - c[0]) / 2.0),
        c[1] + 0.5_f64.min((c[3] - c[1]) / 2.0),
    ]
}

/// The robots' top speed, m/s.
const SPEED: f64 = 0.35;
/// The area of a robot's cell, about (m²).
const CELL_AREA: f64 = 16.0;
/// The distance between a sweep's lanes (m).
const SPACING: f64 = 0.6;

/// The arena's side for `n` robots (m): about 16 m² each.
fn side_of(n: usize) -> f64 {
    (CELL_AREA * n as f64).sqrt().max(4.0)
}

fn cells_mission(
    name: &str,
    n: usize,
    seconds: f64,
    start_cell: impl Fn(usize) -> usize,
    patience: Option<f64>,
) -> (String, String) {
    use std::fmt::Write as _;
    let side = side_of(n);
    // With `patience`, the run's stall limit and the team barrier's
    // deadline (the kernel waits on past it for teammates heard working
    // only while their stacks change: not while they drive and sweep).
    let terminate = patience.map_or("term.wait-all".to_string(), |s| {
        format!("{{ protocol: term.wait-all, deadline: {s}s }}")
    });
    let graph = format!(
        "graph: {name}-{n}\nteam: {{ robots: {n} }}\nstart: cover\ndefaults: {{ terminate: {terminate} }}\n\
         behaviors:\n  cover: {{ team: true, skill: sweep, until: swept }}\n"
    );
    let stall = patience.map_or(String::new(), |s| format!("stall: {{ after: {s}s }}\n"));
    let mut sc = format!(
        "scenario: {name}-{n}\nworld: physics\nseed: 1\ncontrol_hz: 10\ntime_limit: {seconds}s\n{stall}\
         physics:\n  arena: [{side:.2}, {side:.2}]\n  trail: 0\n\
         \x20 robot: {{ radius: 0.12, drive: differential, max_speed: {SPEED}, max_turn: 3, max_accel: 1.0 }}\n\
         \x20 sensors: {{ pose_noise: 0.005, rays: {{ count: 8, range: 1.0, noise: 0.005 }}, camera: {{ fov: 120, range: 3, noise: 0.01 }} }}\n\
         \x20 beliefs: {{ swept: skill_done }}\n  obstacles:\n"
    );
    let pillars = (side / 8.0).floor() as usize;
    for a in 0..pillars {
        for b in 0..pillars {
            let _ = writeln!(
                sc,
                "    - {{ disc: 0.2, at: [{:.2}, {:.2}] }}",
                8.0 * a as f64 + 6.0,
                8.0 * b as f64 + 2.0
            );
        }
    }
    sc.push_str("  start:\n");
    for r in 0..n {
        let [x, y] = cell_start(n, start_cell(r));
        let _ = writeln!(sc, "    r{r}: {{ at: [{x:.2}, {y:.2}] }}");
    }
    let _ = write!(
        sc,
        "skills:\n  sweep:\n    schemas:\n\
         \x20     - {{ schema: scan, region: [0, 0, {side:.2}, {side:.2}], split: true, spacing: {SPACING}, speed: {SPEED}, layer: 1 }}\n\
         \x20     - {{ schema: avoid-teammate, range: 0.4, layer: 2 }}\n\
         \x20     - {{ schema: avoid-obstacle, range: 0.3, layer: 3 }}\n"
    );
    (graph, sc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_robots_start_in_each_others_cells_half_the_arena_away() {
        for n in [2usize, 16, 100, 1000] {
            let side = side_of(n);
            let mut cells: Vec<usize> = (0..n).map(|r| crossing_start_cell(n, r)).collect();
            // Every robot has a start of its own: the same places as the
            // coverage mission's, shared out differently.
            assert!(cells.iter().enumerate().all(|(r, c)| *c != r), "n = {n}");
            cells.sort_unstable();
            assert_eq!(cells, (0..n).collect::<Vec<_>>(), "n = {n}");
            // On average a robot starts about half the arena from its cell
            // on each axis (some 0.7 of the side, diagonally).
            let mean = (0..n)
                .map(|r| {
                    let ([a, b], [c, d]) =
                        (cell_start(n, r), cell_start(n, crossing_start_cell(n, r)));
                    (a - c).hypot(b - d)
                })
                .sum::<f64>()
                / n as f64;
            assert!(
                mean > 0.4 * side && mean < 0.8 * side,
                "n = {n}: {mean} m of {side}"
            );
            // Across both axes, not along one: few robots keep their column.
            let same_column = (0..n)
                .filter(|&r| cell_start(n, r)[0] == cell_start(n, crossing_start_cell(n, r))[0])
                .count();
            assert!(
                same_column * 4 <= n,
                "n = {n}: {same_column} keep their column"
            );
        }
        // The coverage mission is the same text with the robots at home.
        let (cov_graph, cov) = coverage_mission(16, 60.0);
        let (cross_graph, cross) = crossing_mission(16, 60.0);
        let is_start = |l: &&str| l.trim_start().starts_with('r') && l.contains("at:");
        let starts = |s: &str| {
            let mut v: Vec<String> = s
                .lines()
                .filter(is_start)
                .map(|l| l.split_once(':').map_or("", |x| x.1).trim().to_string())
                .collect();
            v.sort();
            v
        };
        assert_eq!(starts(&cov), starts(&cross));
        // Crossing and sweeping take minutes in which nothing is decided:
        // the run is not called stalled, nor does the barrier give up on
        // the last robots, before a robot could have crossed it all and
        // swept its cell ((16 m + 16 m² / 0.6 m) / 0.35 m/s, + 2 min).
        assert!(cross.contains("\nstall: { after: 242s }\n"), "{cross}");
        let barrier = "defaults: { terminate: { protocol: term.wait-all, deadline: 242s } }";
        assert!(cross_graph.contains(barrier), "{cross_graph}");
        assert_eq!(
            cov_graph.replace("coverage", "crossing"),
            cross_graph.replace(barrier, "defaults: { terminate: term.wait-all }")
        );
        // Otherwise the two are the same text.
        let rest = |s: &str| {
            s.lines()
                .filter(|l| !l.starts_with("stall:"))
                .filter(|l| !is_start(l))
                .collect::<Vec<_>>()
                .join("\n")
        };
        assert_eq!(rest(&cov.replace("coverage", "crossing")), rest(&cross));
    }
}
