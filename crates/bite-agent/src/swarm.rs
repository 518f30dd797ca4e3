//! Generated missions for large teams: the coverage task at any team
//! size, for `bite bench sim` and for tests.

/// The coverage mission at scale: `n` robots split a square arena of about
/// 16 m² per robot (pillars every 8 m, mid-lane, away from the lanes' ends)
/// into near-square cells, one each
/// (`scan` with `split`: the cell is the robot's rank in the team), and
/// sweep them. Robots start in their cells, where their sweep begins; the run stops after `seconds`
/// (a cell takes longer than a minute to sweep, so the figure is the
/// steady state of sensing, kernels, fusion and physics).
pub fn coverage_mission(n: usize, seconds: f64) -> (String, String) {
    use std::fmt::Write as _;
    let side = (16.0 * n as f64).sqrt().max(4.0);
    let region = [0.0, 0.0, side, side];
    let graph = format!(
        "graph: coverage-{n}\nteam: {{ robots: {n} }}\nstart: cover\ndefaults: {{ terminate: term.wait-all }}\n\
         behaviors:\n  cover: {{ team: true, skill: sweep, until: swept }}\n"
    );
    let mut sc = format!(
        "scenario: coverage-{n}\nworld: physics\nseed: 1\ncontrol_hz: 10\ntime_limit: {seconds}s\n\
         physics:\n  arena: [{side:.2}, {side:.2}]\n  trail: 0\n\
         \x20 robot: {{ radius: 0.12, drive: differential, max_speed: 0.35, max_turn: 3, max_accel: 1.0 }}\n\
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
        let c = crate::schema::split_cell(region, r as u32, n as u32);
        let _ = writeln!(
            sc,
            "    r{r}: {{ at: [{:.2}, {:.2}] }}",
            // Where its sweep begins: by the cell's lower-left corner
            // (pillars stand mid-cell).
            c[0] + 0.5_f64.min((c[2] - c[0]) / 2.0),
            c[1] + 0.5_f64.min((c[3] - c[1]) / 2.0)
        );
    }
    let _ = write!(
        sc,
        "skills:\n  sweep:\n    schemas:\n\
         \x20     - {{ schema: scan, region: [0, 0, {side:.2}, {side:.2}], split: true, spacing: 0.6, speed: 0.35, layer: 1 }}\n\
         \x20     - {{ schema: avoid-teammate, range: 0.4, layer: 2 }}\n\
         \x20     - {{ schema: avoid-obstacle, range: 0.3, layer: 3 }}\n"
    );
    (graph, sc)
}
