//! Objects placed by the run's seed (`at: { one_of: ... }` or
//! `at: { within: ... }`, see `docs/scenario-format.md`).
//!
//! The draw is part of building the world ([`World::new`](super::World::new)),
//! so every simulator that builds a world from a scenario and a seed (the
//! in-process runner, the Zenoh simulator server) puts the objects in the
//! same places. It is a pure function of the scenario, the team and the
//! seed: one stream derived from the seed (`derive_seed(seed, "place", 0)`),
//! every drawn object drawn again together until all of them are clear of
//! everything and, with `out_of_sight`, unseen by every robot at its start
//! pose — as the camera model sees, with its range, field of view and line
//! of sight — or a located error after [`MAX_DRAWS`] draws.

use super::{Kind, PhysicsSpec, Shape, start_poses, v32};
use bite_agent::agent::derive_seed;
use bite_agent::schema;
use bite_agent::spec::Draw;
use bite_core::diag::Diagnostic;
use bite_core::interaction::Rng;
use glam::DVec2;
use rand::SeedableRng;
use rapier2d::prelude as rp;
use std::sync::Arc;

/// Draws of the drawn objects before the world gives up.
pub const MAX_DRAWS: u32 = 1000;

/// Why a draw was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Refused {
    /// Closer than a robot radius to a wall, an obstacle, another object or
    /// a robot.
    Crowded,
    /// A robot's camera sees it from where the robot starts.
    InSight,
}

/// A solid the draw keeps clear of, or that stands in a camera's way.
struct Solid {
    kind: Kind,
    shape: rp::SharedShape,
    pose: rp::Pose,
}

fn shape_of(shape: &Shape) -> rp::SharedShape {
    match shape {
        Shape::Box(s) => rp::SharedShape::cuboid(s.x as f32 / 2.0, s.y as f32 / 2.0),
        Shape::Disc(r) => rp::SharedShape::ball(*r as f32),
    }
}

/// Half the thickness of the arena's walls, m.
pub(super) const WALL_HALF: f32 = 0.1;

/// The walls round the arena, as the world builds them.
pub(super) fn walls(arena: DVec2) -> [(rp::Vector, rp::Vector); 4] {
    let (w, h) = (arena.x as f32, arena.y as f32);
    let t = WALL_HALF;
    [
        (
            rp::Vector::new(w / 2.0, -t),
            rp::Vector::new(w / 2.0 + t, t),
        ),
        (
            rp::Vector::new(w / 2.0, h + t),
            rp::Vector::new(w / 2.0 + t, t),
        ),
        (
            rp::Vector::new(-t, h / 2.0),
            rp::Vector::new(t, h / 2.0 + t),
        ),
        (
            rp::Vector::new(w + t, h / 2.0),
            rp::Vector::new(t, h / 2.0 + t),
        ),
    ]
}

/// One draw of a position.
fn draw(d: &Draw, rng: &mut Rng) -> DVec2 {
    use rand::RngExt;
    match d {
        Draw::OneOf(points) => points[rng.random_range(0..points.len())],
        Draw::Within([x0, y0, x1, y1]) => {
            DVec2::new(rng.random_range(*x0..=*x1), rng.random_range(*y0..=*y1))
        }
    }
}

/// The scenario's world with every drawn object where this run puts it
/// (the same `spec` when the scenario draws none).
pub(super) fn place(
    spec: &Arc<PhysicsSpec>,
    names: &[String],
    seed: u64,
    file: &Arc<str>,
) -> Result<Arc<PhysicsSpec>, Diagnostic> {
    let drawn: Vec<usize> = (spec.objects.iter().enumerate())
        .filter(|(_, o)| o.place.is_some())
        .map(|(k, _)| k)
        .collect();
    if drawn.is_empty() {
        return Ok(spec.clone());
    }
    let mut rng = Rng::seed_from_u64(derive_seed(seed, "place", 0));
    let mut trial = (**spec).clone();
    // Refusals per object: crowded, in sight.
    let mut refused = vec![(0u32, 0u32); spec.objects.len()];
    for _ in 0..MAX_DRAWS {
        for &k in &drawn {
            if let Some(p) = &spec.objects[k].place {
                trial.objects[k].at = draw(&p.draw, &mut rng);
            }
        }
        let solids = solids(&trial, names);
        let mut ok = true;
        for &k in &drawn {
            match check(&trial, &solids, k) {
                Ok(()) => {}
                Err(Refused::Crowded) => {
                    refused[k].0 += 1;
                    ok = false;
                }
                Err(Refused::InSight) => {
                    refused[k].1 += 1;
                    ok = false;
                }
            }
        }
        if ok {
            return Ok(Arc::new(trial));
        }
    }
    // The object refused most often is the one to move.
    let k = drawn
        .iter()
        .copied()
        .max_by_key(|&k| (refused[k].0 + refused[k].1, std::cmp::Reverse(k)))
        .unwrap_or(drawn[0]);
    let o = &spec.objects[k];
    let Some(p) = &o.place else {
        unreachable!("drawn objects have a placement")
    };
    let (crowded, seen) = refused[k];
    let name = o.name.as_deref().unwrap_or("?");
    let mut why = format!("{crowded} too close to something");
    if p.out_of_sight {
        why.push_str(&format!(", {seen} in sight of a robot at its start"));
    }
    Err(Diagnostic::error(
        file,
        p.loc,
        "no-place",
        format!("no place for object `{name}` in {MAX_DRAWS} draws with seed {seed} ({why})"),
    )
    .with_hint(if p.out_of_sight {
        "widen `within` or add `one_of` points out of the robots' view (their start poses, \
         camera range and field of view), or drop `out_of_sight`"
    } else {
        "widen `within` or add `one_of` points clear of walls, obstacles, objects and robots"
    }))
}

/// Everything in the arena at the start: walls, obstacles, objects where
/// `spec` has them, robots at their start poses.
fn solids(spec: &PhysicsSpec, names: &[String]) -> Vec<Solid> {
    // In the order the camera's ray meets them in the world (robots,
    // objects, obstacles, walls), so that a tie goes the same way.
    let mut out = Vec::new();
    for (i, pose) in start_poses(spec, names).into_iter().enumerate() {
        // A robot without a place is the world's error, reported there.
        if let Some((at, heading)) = pose {
            out.push(Solid {
                kind: Kind::Robot(i),
                shape: rp::SharedShape::ball(spec.robot.radius as f32),
                pose: rp::Pose::new(v32(at), heading as f32),
            });
        }
    }
    for (k, o) in spec.objects.iter().enumerate() {
        out.push(Solid {
            kind: Kind::Object(k),
            shape: shape_of(&o.shape),
            pose: rp::Pose::new(v32(o.at), o.angle as f32),
        });
    }
    for o in &spec.obstacles {
        out.push(Solid {
            kind: Kind::Obstacle,
            shape: shape_of(&o.shape),
            pose: rp::Pose::new(v32(o.at), o.angle as f32),
        });
    }
    for (at, half) in walls(spec.arena) {
        out.push(Solid {
            kind: Kind::Wall,
            shape: rp::SharedShape::cuboid(half.x, half.y),
            pose: rp::Pose::new(at, 0.0),
        });
    }
    out
}

/// Is object `k` clear of everything, and (if it must be) out of every
/// robot's sight?
fn check(spec: &PhysicsSpec, solids: &[Solid], k: usize) -> Result<(), Refused> {
    let me = solids
        .iter()
        .find(|s| s.kind == Kind::Object(k))
        .ok_or(Refused::Crowded)?;
    let gap = spec.robot.radius as f32;
    for s in solids.iter().filter(|s| s.kind != me.kind) {
        let d = rapier2d::parry::query::distance(&me.pose, &*me.shape, &s.pose, &*s.shape)
            .map_or(0.0, |d| d.distance);
        if d < gap {
            return Err(Refused::Crowded);
        }
    }
    if spec.objects[k]
        .place
        .as_ref()
        .is_some_and(|p| p.out_of_sight)
    {
        let at = DVec2::new(me.pose.translation.x as f64, me.pose.translation.y as f64);
        for s in solids {
            if let Kind::Robot(i) = s.kind
                && sees(spec, solids, i, s, at, me.kind)
            {
                return Err(Refused::InSight);
            }
        }
    }
    Ok(())
}

/// Does robot `i` (the solid `robot`) see `target` at `at`? The camera's
/// test, as [`World::observe`](super::World::observe) makes it: within
/// range and field of view, and the first thing the ray from the robot's
/// centre toward the target hits is the target itself.
fn sees(
    spec: &PhysicsSpec,
    solids: &[Solid],
    i: usize,
    robot: &Solid,
    at: DVec2,
    target: Kind,
) -> bool {
    let s = spec.sensors;
    let from = DVec2::new(
        robot.pose.translation.x as f64,
        robot.pose.translation.y as f64,
    );
    let heading = robot.pose.rotation.angle() as f64;
    let off = at - from;
    let len = off.length();
    let bearing = schema::wrap(off.y.atan2(off.x) - heading);
    if len > s.camera_range || bearing.abs() > s.fov / 2.0 {
        return false;
    }
    if len <= 1e-9 {
        return true;
    }
    let dir = off / len;
    let ray = rp::Ray::new(v32(from), v32(dir));
    let mut best: Option<(Kind, f32)> = None;
    for o in solids.iter().filter(|o| o.kind != Kind::Robot(i)) {
        if let Some(toi) = o.shape.cast_ray(&o.pose, &ray, len as f32, true)
            && best.is_none_or(|(_, b)| toi < b)
        {
            best = Some((o.kind, toi));
        }
    }
    best.is_none_or(|(k, _)| k == target)
}

#[cfg(test)]
mod tests {
    use super::super::World;
    use super::*;

    /// Two robots at the search-rescue start, facing into a 7 × 4 m hall
    /// with a chair; a box drawn by `at` (line 12) and a crate.
    fn hall(at: &str) -> (bite_core::graph::BehaviorGraph, Arc<PhysicsSpec>) {
        let g = "graph: g\nteam: { robots: 2 }\nstart: a\nbehaviors:\n  a: { team: true }\n";
        let g = bite_core::graph::load_str(&Arc::from("g.yaml"), g).expect("graph");
        let s = format!(
            "scenario: s\nworld: physics\nphysics:\n  arena: [7, 4]\n  robot: {{ radius: 0.12 }}\n  \
             start:\n    r0: {{ at: [1.3, 1.2], heading: 0 }}\n    r1: {{ at: [1.3, 1.8], heading: 20 }}\n  \
             obstacles:\n    - {{ disc: 0.2, at: [3.2, 1.2] }}\n  objects:\n    \
             - {{ name: box, box: [0.3, 0.3], at: {at} }}\n    \
             - {{ name: crate, box: [0.3, 0.3], at: [3.8, 0.8] }}\n  \
             sensors:\n    camera: {{ fov: 120, range: 5 }}\n"
        );
        let sc =
            crate::Scenario::load_str(&Arc::from("s.yaml"), &s).unwrap_or_else(|d| panic!("{d}"));
        (g, sc.physics.clone().expect("physical"))
    }

    const NAMES: [&str; 2] = ["r0", "r1"];

    fn world(spec: &Arc<PhysicsSpec>, g: &bite_core::graph::BehaviorGraph, seed: u64) -> World {
        let names: Vec<String> = NAMES.iter().map(|n| n.to_string()).collect();
        World::new(
            spec.clone(),
            &names,
            g.symbols(),
            &Arc::from("s.yaml"),
            seed,
        )
        .unwrap_or_else(|d| panic!("seed {seed}: {d}"))
    }

    /// Does some robot's camera see object `k` now?
    fn seen(w: &mut World, k: usize) -> bool {
        (0..NAMES.len()).any(|i| w.observe(i).objects.iter().any(|(o, _)| *o == k))
    }

    #[test]
    fn the_same_seed_draws_the_same_place_and_other_seeds_others() {
        let (g, spec) = hall("{ within: [2, 0.3, 6.7, 3.7] }");
        let a = world(&spec, &g, 7).object_pos(0);
        let b = world(&spec, &g, 7).object_pos(0);
        assert_eq!(a, b, "seed 7 twice");
        // A scenario loaded again gives the same place: the draw depends on
        // nothing but the scenario, the team and the seed.
        let (g2, spec2) = hall("{ within: [2, 0.3, 6.7, 3.7] }");
        assert_eq!(world(&spec2, &g2, 7).object_pos(0), a);
        let places: Vec<DVec2> = (1..=20)
            .map(|s| world(&spec, &g, s).object_pos(0))
            .collect();
        for (i, p) in places.iter().enumerate() {
            assert!(
                (2.0..=6.7).contains(&p.x) && (0.3..=3.7).contains(&p.y),
                "seed {}: {p} outside `within`",
                i + 1
            );
            for (j, q) in places[..i].iter().enumerate() {
                assert!(
                    p != q,
                    "seeds {} and {} draw the same place {p}",
                    j + 1,
                    i + 1
                );
            }
        }
        // The fixed crate stays where it is written.
        let crate_at = world(&spec, &g, 3).object_pos(1);
        assert!(crate_at.distance(DVec2::new(3.8, 0.8)) < 1e-6, "{crate_at}");
        // `one_of` takes one of its points, and more than one over seeds.
        let (g, spec) = hall("{ one_of: [[5, 1], [5, 3], [6, 2]] }");
        let mut picked: Vec<DVec2> = (1..=20)
            .map(|s| world(&spec, &g, s).object_pos(0))
            .collect();
        picked.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
        picked.dedup();
        assert_eq!(picked.len(), 3, "{picked:?}");
    }

    #[test]
    fn an_object_out_of_sight_is_unseen_by_every_camera_at_the_start() {
        let (g, spec) = hall("{ within: [2, 0.3, 6.7, 3.7], out_of_sight: true }");
        let (g_any, spec_any) = hall("{ within: [2, 0.3, 6.7, 3.7] }");
        let mut seen_without = 0;
        for seed in 1..=40 {
            let mut w = world(&spec, &g, seed);
            assert!(
                !seen(&mut w, 0),
                "seed {seed}: box at {} in sight",
                w.object_pos(0)
            );
            // Clear of the chair, the crate, the robots and the walls.
            let p = w.object_pos(0);
            assert!(
                p.distance(DVec2::new(3.2, 1.2)) > 0.2 + 0.15,
                "seed {seed}: {p}"
            );
            assert!(p.distance(DVec2::new(3.8, 0.8)) > 0.3, "seed {seed}: {p}");
            for i in 0..2 {
                assert!(p.distance(w.pose(i).pos) > 0.12 + 0.15, "seed {seed}: {p}");
            }
            let gap = 0.15 + 0.12 - 1e-4;
            assert!(p.x >= gap && p.x <= 7.0 - gap && p.y >= gap && p.y <= 4.0 - gap);
            // Without `out_of_sight`, the same region is mostly in view.
            let mut w = world(&spec_any, &g_any, seed);
            if seen(&mut w, 0) {
                seen_without += 1;
            }
        }
        assert!(
            seen_without > 20,
            "only {seen_without} of 40 in sight without the check"
        );
    }

    #[test]
    fn no_place_out_of_sight_is_an_error_at_the_draw() {
        // Right in front of both robots.
        let (g, spec) = hall("{ within: [2, 1.3, 2.5, 1.7], out_of_sight: true }");
        let names: Vec<String> = NAMES.iter().map(|n| n.to_string()).collect();
        let e = World::new(spec, &names, g.symbols(), &Arc::from("s.yaml"), 1)
            .expect_err("no place")
            .to_string();
        assert!(e.contains("s.yaml:12:"), "{e}");
        assert!(e.contains("error[no-place]"), "{e}");
        assert!(
            e.contains("no place for object `box` in 1000 draws with seed 1"),
            "{e}"
        );
        assert!(e.contains("in sight of a robot"), "{e}");
        // Inside the chair, whatever the seed.
        let (g, spec) = hall("{ one_of: [[3.2, 1.2]] }");
        let e = World::new(spec, &names, g.symbols(), &Arc::from("s.yaml"), 1)
            .expect_err("no place")
            .to_string();
        assert!(e.contains("1000 too close to something"), "{e}");
    }
}
