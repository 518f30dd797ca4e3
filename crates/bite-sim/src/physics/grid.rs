//! Where everything is at a control tick, for sensing: every collider's
//! bounding box bucketed into square cells, rebuilt once per tick.
//!
//! A robot senses what is within its reach (camera range, or ray range
//! plus its radius). It used to ask the physics engine's bounding-volume
//! hierarchy, whose boxes are fattened and as of the last step, at the
//! price of a walk down a tree of 10,000 leaves per robot (scattered
//! nodes: cache misses). This grid holds the boxes as of now, in one
//! array ordered by cell, so a robot's question reads two to four cells
//! side by side. What sensing reads of the answer does not depend on
//! which structure gave it: the answer is sorted, and rays and the
//! camera test every collider exactly, so any superset of what is within
//! reach gives the same readings (see `near` in the parent module).

use super::Kind;
use glam::DVec2;
use rapier2d::prelude as rp;

/// Cells along an axis at most: a collider far outside the arena makes
/// the cells larger, never the grid larger.
const MAX_CELLS: usize = 1024;

/// Every collider's box as of one physics step, bucketed into cells.
#[derive(Debug, Default)]
pub(super) struct Grid {
    /// The physics step it was built at (`None`: never built).
    step: Option<u64>,
    origin: [f32; 2],
    cell: f32,
    nx: usize,
    ny: usize,
    /// Entries of cell `c` are `items[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    /// Indices into `entries`, cell by cell.
    items: Vec<u32>,
    /// Each collider: its box, the cells it overlaps, what it is.
    entries: Vec<Entry>,
    /// Where the next entry of each cell goes, while it is built.
    fill: Vec<u32>,
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    aabb: rp::Aabb,
    /// The first and last cell it overlaps along each axis.
    first: [u32; 2],
    last: [u32; 2],
    kind: Kind,
    handle: rp::ColliderHandle,
}

impl Grid {
    /// Is it as of physics step `step`?
    pub(super) fn is_at(&self, step: u64) -> bool {
        self.step == Some(step)
    }

    /// Rebuild it from `colliders` as they are at physics step `step`,
    /// with cells of `cell` metres at least (queries of up to half that
    /// range read at most two cells along each axis).
    pub(super) fn rebuild(
        &mut self,
        step: u64,
        cell: f32,
        colliders: impl Iterator<Item = (rp::Aabb, Kind, rp::ColliderHandle)>,
    ) {
        self.step = Some(step);
        self.entries.clear();
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for (aabb, kind, handle) in colliders {
            // A box with no extent we can place (not finite) is nowhere a
            // sensor could find it either.
            if !(aabb.mins.is_finite() && aabb.maxs.is_finite()) {
                continue;
            }
            lo = [lo[0].min(aabb.mins.x), lo[1].min(aabb.mins.y)];
            hi = [hi[0].max(aabb.maxs.x), hi[1].max(aabb.maxs.y)];
            self.entries.push(Entry {
                aabb,
                first: [0, 0],
                last: [0, 0],
                kind,
                handle,
            });
        }
        if self.entries.is_empty() {
            (self.nx, self.ny) = (1, 1);
            self.starts.clear();
            self.starts.extend([0, 0]);
            self.items.clear();
            return;
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        self.cell = cell.max(extent / MAX_CELLS as f32).max(f32::MIN_POSITIVE);
        self.origin = lo;
        let cells = |w: f32| ((w / self.cell) as usize + 1).min(MAX_CELLS);
        (self.nx, self.ny) = (cells(hi[0] - lo[0]), cells(hi[1] - lo[1]));
        // Counting sort of (entry, cell) pairs by cell.
        self.starts.clear();
        self.starts.resize(self.nx * self.ny + 1, 0);
        for k in 0..self.entries.len() {
            let e = self.entries[k];
            let ([x0, y0], [x1, y1]) = self.span(e.aabb.mins, e.aabb.maxs);
            self.entries[k].first = [x0 as u32, y0 as u32];
            self.entries[k].last = [x1 as u32, y1 as u32];
            for y in y0..=y1 {
                for x in x0..=x1 {
                    self.starts[y * self.nx + x + 1] += 1;
                }
            }
        }
        for c in 1..self.starts.len() {
            self.starts[c] += self.starts[c - 1];
        }
        let total = self.starts[self.starts.len() - 1] as usize;
        self.items.clear();
        self.items.resize(total, 0);
        let mut fill = std::mem::take(&mut self.fill);
        fill.clear();
        fill.extend_from_slice(&self.starts[..self.starts.len() - 1]);
        for (k, e) in self.entries.iter().enumerate() {
            let ([x0, y0], [x1, y1]) = (e.first, e.last);
            for y in y0 as usize..=y1 as usize {
                for x in x0 as usize..=x1 as usize {
                    let c = y * self.nx + x;
                    self.items[fill[c] as usize] = k as u32;
                    fill[c] += 1;
                }
            }
        }
        self.fill = fill;
    }

    /// The cells (first and last along each axis) a box overlaps,
    /// clamped to the grid.
    fn span(&self, mins: rp::Vector, maxs: rp::Vector) -> ([usize; 2], [usize; 2]) {
        let at = |v: f32, o: f32, n: usize| {
            let c = ((v - o) / self.cell).floor();
            if c.is_nan() || c <= 0.0 {
                0
            } else {
                (c as usize).min(n - 1)
            }
        };
        (
            [
                at(mins.x, self.origin[0], self.nx),
                at(mins.y, self.origin[1], self.ny),
            ],
            [
                at(maxs.x, self.origin[0], self.nx),
                at(maxs.y, self.origin[1], self.ny),
            ],
        )
    }

    /// Every collider whose box overlaps the square of half side `range`
    /// around `at`, but `skip`, each once, in no particular order.
    pub(super) fn query(
        &self,
        at: DVec2,
        range: f64,
        skip: Kind,
        out: &mut Vec<(Kind, rp::ColliderHandle)>,
    ) {
        if self.entries.is_empty() {
            return;
        }
        let r = rp::Vector::new(range as f32, range as f32);
        let c = rp::Vector::new(at.x as f32, at.y as f32);
        let (qmin, qmax) = (c - r, c + r);
        let ([x0, y0], [x1, y1]) = self.span(qmin, qmax);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let cell = y * self.nx + x;
                let (from, to) = (self.starts[cell] as usize, self.starts[cell + 1] as usize);
                for &k in &self.items[from..to] {
                    let e = &self.entries[k as usize];
                    // An entry in several of these cells is reported from
                    // the first of them only.
                    if x != (e.first[0] as usize).max(x0) || y != (e.first[1] as usize).max(y0) {
                        continue;
                    }
                    let overlaps = e.aabb.mins.x <= qmax.x
                        && qmin.x <= e.aabb.maxs.x
                        && e.aabb.mins.y <= qmax.y
                        && qmin.y <= e.aabb.maxs.y;
                    if overlaps && e.kind != skip {
                        out.push((e.kind, e.handle));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn aabb(x0: f32, y0: f32, x1: f32, y1: f32) -> rp::Aabb {
        rp::Aabb::new(rp::Vector::new(x0, y0), rp::Vector::new(x1, y1))
    }

    fn handle(i: u32) -> rp::ColliderHandle {
        rp::ColliderHandle::from_raw_parts(i, 0)
    }

    /// What a scan of every box answers, sorted.
    fn scan(boxes: &[(rp::Aabb, Kind)], at: DVec2, range: f32, skip: Kind) -> Vec<usize> {
        let mut out: Vec<usize> = (boxes.iter().enumerate())
            .filter(|(_, (b, k))| {
                *k != skip
                    && b.mins.x <= at.x as f32 + range
                    && at.x as f32 - range <= b.maxs.x
                    && b.mins.y <= at.y as f32 + range
                    && at.y as f32 - range <= b.maxs.y
            })
            .map(|(i, _)| i)
            .collect();
        out.sort_unstable();
        out
    }

    #[test]
    fn a_query_answers_what_a_scan_does_each_collider_once() {
        // Walls spanning many cells, small robots, a box outside the
        // arena, one on a cell border, and queries everywhere.
        let mut boxes = vec![
            (aabb(-0.1, -0.1, 40.0, 0.1), Kind::Wall),
            (aabb(-0.1, -0.1, 0.1, 40.0), Kind::Wall),
            (aabb(39.9, -0.1, 40.1, 40.0), Kind::Wall),
            (aabb(13.8, 13.8, 14.2, 14.2), Kind::Obstacle),
            (aabb(-30.0, 50.0, -29.0, 51.0), Kind::Object(0)),
        ];
        for i in 0..200 {
            let (x, y) = ((i * 37 % 400) as f32 / 10.0, (i * 91 % 400) as f32 / 10.0);
            boxes.push((aabb(x - 0.12, y - 0.12, x + 0.12, y + 0.12), Kind::Robot(i)));
        }
        let mut g = Grid::default();
        g.rebuild(
            7,
            7.0,
            (boxes.iter().enumerate()).map(|(i, (b, k))| (*b, *k, handle(i as u32))),
        );
        assert!(g.is_at(7) && !g.is_at(8));
        let mut out = Vec::new();
        for q in 0..300 {
            let at = DVec2::new(
                (q * 53 % 500) as f64 / 10.0 - 5.0,
                (q * 29 % 500) as f64 / 10.0 - 5.0,
            );
            let skip = Kind::Robot(q % 200);
            out.clear();
            g.query(at, 3.5, skip, &mut out);
            let mut got: Vec<usize> = out
                .iter()
                .map(|(_, h)| h.into_raw_parts().0 as usize)
                .collect();
            got.sort_unstable();
            let n = got.len();
            got.dedup();
            assert_eq!(n, got.len(), "query {q} at {at}: a collider reported twice");
            assert_eq!(got, scan(&boxes, at, 3.5, skip), "query {q} at {at}");
        }
        // Far outside: the box outside the arena, found from near it.
        out.clear();
        g.query(DVec2::new(-29.5, 50.5), 1.0, Kind::Wall, &mut out);
        assert_eq!(out.len(), 1);
    }

    #[test]
    fn an_empty_world_has_nothing_near() {
        let mut g = Grid::default();
        g.rebuild(0, 7.0, std::iter::empty());
        let mut out = Vec::new();
        g.query(DVec2::ZERO, 3.0, Kind::Wall, &mut out);
        assert!(out.is_empty());
    }
}
