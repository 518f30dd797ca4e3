//! The linear assignment problem: Jonker-Volgenant (LAPJV), rectangular.
//!
//! R. Jonker and A. Volgenant, *A shortest augmenting path algorithm for
//! dense and sparse linear assignment problems*, Computing 38 (1987). The
//! phases are an initialisation (column reduction and reduction transfer
//! on a square matrix), two rounds of augmenting row reduction (which
//! assign most rows cheaply), then a Dijkstra-like shortest augmenting path
//! for each row still free. Dense, `O(n²m)` worst case, far faster on
//! typical instances (see `docs/performance.md`, where it is measured
//! against SciPy's `linear_sum_assignment`). The shortest-path scans run
//! four columns at a time in column order ([`scan_row`]); the choices
//! among ties are replayed in JV's own order, so the assignment is the
//! one JV's scalar scans give, ties included.
//!
//! Rectangular problems are solved as they are, not padded to a square:
//! with `n` rows and `m ≥ n` columns only `n` rows are assigned, so the
//! initialisation starts every column's dual at 0 and the duals of the
//! columns left unassigned stay there (see [`lapjv`]). More rows than
//! columns is solved on the transpose.

// The algorithm walks parallel arrays (costs, duals, row and column
// assignments) by index; iterator rewrites would obscure it.
#![allow(clippy::needless_range_loop)]

use wide::f64x4;

/// An optimal assignment: `row_to_col[i]` is the column of row `i`, or
/// `None` if the row is unassigned (more rows than columns).
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// Column assigned to each row.
    pub row_to_col: Vec<Option<usize>>,
    /// Total cost of the assigned pairs.
    pub cost: f64,
}

/// Minimize the total cost of assigning rows to distinct columns. `cost` is
/// row-major, `rows × cols`. Every row is assigned if `rows ≤ cols`, else
/// every column is. Non-finite costs are treated as very large.
pub fn solve(rows: usize, cols: usize, cost: &[f64]) -> Solution {
    if rows == 0 || cols == 0 || cost.len() != rows * cols {
        return Solution {
            row_to_col: vec![None; rows],
            cost: 0.0,
        };
    }
    let n = rows.max(cols);
    // Finite stand-in for impossible pairs, large enough never to be chosen
    // over a finite one when a finite one exists.
    // (A fold without early exit, so that it vectorizes: this pass is a
    // visible share of the time on easy instances.)
    let all_finite = cost.iter().fold(true, |ok, c| ok & c.is_finite());
    let big = if all_finite {
        0.0 // not used
    } else {
        let finite_max = cost
            .iter()
            .filter(|c| c.is_finite())
            .fold(0.0f64, |m, c| m.max(c.abs()));
        (finite_max + 1.0) * (n as f64 + 1.0)
    };
    let fix = |v: f64| if v.is_finite() { v } else { big };
    let row_to_col: Vec<Option<usize>> = if rows <= cols {
        // The caller's matrix is used as it is unless a cost must be replaced.
        let owned: Vec<f64>;
        let c: &[f64] = if all_finite {
            cost
        } else {
            owned = cost.iter().map(|v| fix(*v)).collect();
            &owned
        };
        lapjv(rows, cols, c).into_iter().map(Some).collect()
    } else {
        // Columns become rows: `cols × rows`, copied in blocks so that both
        // sides stay in cache.
        const B: usize = 32;
        let mut t = vec![0.0f64; rows * cols];
        for i0 in (0..rows).step_by(B) {
            for j0 in (0..cols).step_by(B) {
                for i in i0..(i0 + B).min(rows) {
                    let src = &cost[i * cols..(i + 1) * cols];
                    for j in j0..(j0 + B).min(cols) {
                        t[j * rows + i] = fix(src[j]);
                    }
                }
            }
        }
        let mut r = vec![None; rows];
        for (j, i) in lapjv(cols, rows, &t).into_iter().enumerate() {
            r[i] = Some(j);
        }
        r
    };
    let total = row_to_col
        .iter()
        .enumerate()
        .filter_map(|(i, j)| j.map(|j| cost[i * cols + j]))
        .sum();
    Solution {
        row_to_col,
        cost: total,
    }
}

const NONE: usize = usize::MAX;

/// Bound on the augmenting row reduction's steps, per row of the problem.
const ARR_STEPS_PER_ROW: usize = 4;

/// Evictions between tied columns the augmenting row reduction makes on a
/// square problem before it leaves such rows to the shortest-path phase.
const ARR_TIE_EVICTIONS: usize = 512;

/// LAPJV on an `n × m` row-major matrix of finite costs, `n ≤ m`; returns
/// the column of each row.
///
/// Why the rectangular case is correct: the shortest-path phase keeps every
/// reduced cost `c[i][j] − u[i] − v[j]` non-negative and zero on assigned
/// pairs, and only ever lowers the duals `v` of columns that are assigned
/// (and stay assigned). A column left unassigned thus keeps the highest
/// dual, which is the optimality condition when not every column is used
/// (complementary slackness: only assigned columns may have `v` below the
/// free ones). The square initialisation (column reduction) gives every
/// column its own dual, so it is used only when `n = m`, where every column
/// ends up assigned; otherwise all duals start at 0.
fn lapjv(n: usize, m: usize, c: &[f64]) -> Vec<usize> {
    debug_assert!(n <= m && c.len() == n * m);
    let row = |i: usize| &c[i * m..(i + 1) * m];
    let mut x = vec![NONE; n]; // row -> column
    let mut y = vec![NONE; m]; // column -> row
    let mut v = vec![0.0f64; m]; // column duals
    let mut free: Vec<usize> = if n == m {
        column_reduction(n, c, &mut x, &mut y, &mut v)
    } else {
        (0..n).collect()
    };

    // Ties in the augmenting row reduction: a row whose two cheapest
    // columns tie and are both taken can only evict a row without lowering
    // any dual, i.e. without progress. On integer or constant costs nearly
    // every step is such a tie and the phase only shuffles rows. The first
    // `tie_budget` of these evictions are made as JV makes them (so square
    // problems up to about 150 × 150 get the very assignment this solver
    // always gave them, ties included: `alloc.optimal`'s decisions); after
    // that the row is left to the shortest-path phase, which settles a tie
    // in one pass over the row. Rectangular problems have no earlier
    // assignment to keep.
    let mut tie_budget = if n == m { ARR_TIE_EVICTIONS } else { 0 };
    let mut left_on_ties = false;
    // Augmenting row reduction, twice.
    for _ in 0..2 {
        if left_on_ties {
            // The second round would meet the same ties again.
            break;
        }
        let mut k = 0;
        let mut current: Vec<usize> = std::mem::take(&mut free);
        // On costs with many near-ties (distances between random points)
        // rows can evict each other for a very long time, lowering a dual
        // by a hair each time. Every step keeps each assigned row on its
        // cheapest column, so stopping early is safe: the rows left go to
        // the exact shortest-path phase.
        let mut steps = 0usize;
        while k < current.len() {
            steps += 1;
            if steps > ARR_STEPS_PER_ROW * n {
                free.extend(current[k..].iter().copied().filter(|i| x[*i] == NONE));
                break;
            }
            let i = current[k];
            k += 1;
            let ci = row(i);
            let (mut umin, mut j1) = (ci[0] - v[0], 0);
            let (mut usubmin, mut j2) = (f64::INFINITY, NONE);
            for j in 1..m {
                let h = ci[j] - v[j];
                if h < usubmin {
                    if h >= umin {
                        usubmin = h;
                        j2 = j;
                    } else {
                        usubmin = umin;
                        j2 = j1;
                        umin = h;
                        j1 = j;
                    }
                }
            }
            let mut i0 = y[j1];
            if umin < usubmin {
                // Make j1 as attractive as the second best for the others.
                v[j1] -= usubmin - umin;
            } else if i0 != NONE && j2 != NONE {
                if y[j2] != NONE {
                    if tie_budget == 0 {
                        // The rows left are as likely to tie: all of them
                        // go to the shortest-path phase.
                        left_on_ties = true;
                        free.push(i);
                        free.extend(current[k..].iter().copied().filter(|i| x[*i] == NONE));
                        break;
                    }
                    tie_budget -= 1;
                }
                // Tie: take the second best column instead of evicting.
                j1 = j2;
                i0 = y[j2];
            }
            x[i] = j1;
            y[j1] = i;
            if i0 != NONE {
                x[i0] = NONE;
                if umin < usubmin {
                    // Reconsider the evicted row in this round.
                    k -= 1;
                    current[k] = i0;
                } else {
                    free.push(i0);
                }
            }
        }
    }

    // Shortest augmenting paths for the remaining free rows.
    //
    // JV keeps the columns in `collist` order: scanned ("ready") first,
    // then those at the current minimum distance (to scan), then the rest
    // ("todo"), and each scan walks the todo part in that order. Here the
    // scan's arithmetic runs over all columns in their own order instead,
    // four at a time (`scan_row`), so that it reads the cost row, duals and
    // distances in sequence rather than gathering them through `collist`:
    // a column that left the todo part has its distance parked in `dfix`
    // and `d[j] = −∞`, so no scan lowers it. Updating a todo column that JV
    // would not reach (the scan stops at the path's end) changes nothing
    // that is read afterwards: `d` and `pred` are set afresh for each free
    // row. What depends on the order, the columns a scan brings to the
    // minimum (`ties`), is replayed in `collist` order (`pos` is its
    // inverse), so every choice among ties is JV's own.
    let mut d = vec![0.0f64; m];
    let mut dfix = vec![0.0f64; m];
    // A column's predecessor row, as an f64 (exact below 2⁵³) so that the
    // scan selects it with the same lane mask as the distance.
    let mut pred = vec![0.0f64; m];
    let mut collist = vec![0usize; m];
    let mut pos = vec![0usize; m];
    let mut ties: Vec<usize> = Vec::new();
    for &freerow in &free {
        if x[freerow] != NONE {
            continue;
        }
        let cf = row(freerow);
        // The reduced costs and their minimum in one pass (a branch-free
        // minimum, so that it vectorizes).
        let mut lowest = f64::INFINITY;
        for ((dj, cj), vj) in d.iter_mut().zip(cf).zip(&v) {
            *dj = cj - vj;
            lowest = if *dj < lowest { *dj } else { lowest };
        }
        // A free column at that minimum ends the path at once: the first
        // collection below would find the same one (it scans the columns in
        // order and keeps the first free one at the final minimum) and
        // change no dual (none is scanned yet). On integer or constant
        // costs most rows end so, and collecting every tied column first
        // was most of the time.
        if let Some(j) = (0..m).find(|&j| d[j] == lowest && y[j] == NONE) {
            y[j] = freerow;
            x[freerow] = j;
            continue;
        }
        pred.fill(freerow as f64);
        for j in 0..m {
            collist[j] = j;
            pos[j] = j;
        }
        let (mut low, mut up) = (0usize, 0usize);
        let mut last = 0usize;
        let mut min = 0.0f64;
        let mut endofpath = NONE;
        while endofpath == NONE {
            if up == low {
                // Collect the columns at the new minimum distance. The scan
                // starts where `up` was; moving `up` inside is intended.
                // The first unassigned column met at the minimum (in the
                // order the set is collected) ends the path, as JV's scan
                // of the set after collecting it would find; noting it on
                // the way saves that second pass.
                last = low;
                let first = collist[up];
                min = d[first];
                let mut free_at_min = if y[first] == NONE { first } else { NONE };
                up += 1;
                #[allow(clippy::mut_range_bound)]
                for k in up..m {
                    let j = collist[k];
                    let h = d[j];
                    if h <= min {
                        if h < min {
                            up = low;
                            min = h;
                            free_at_min = NONE;
                        }
                        if free_at_min == NONE && y[j] == NONE {
                            free_at_min = j;
                        }
                        swap_positions(&mut collist, &mut pos, k, up);
                        up += 1;
                    }
                }
                endofpath = free_at_min;
                if endofpath == NONE {
                    for &j in &collist[low..up] {
                        dfix[j] = d[j];
                        d[j] = f64::NEG_INFINITY;
                    }
                }
            }
            if endofpath == NONE {
                // Scan one column of the minimum set.
                let j1 = collist[low];
                low += 1;
                let i = y[j1];
                let ci = row(i);
                let h = ci[j1] - v[j1] - min;
                scan_row(ci, &v, h, min, i as f64, &mut d, &mut pred, &mut ties);
                // The columns this scan brought to the minimum, in JV's
                // order: the first free one ends the path, the others join
                // the set to scan.
                if ties.len() > 1 {
                    ties.sort_unstable_by_key(|&j| pos[j]);
                }
                for &j in &ties {
                    if y[j] == NONE {
                        endofpath = j;
                        break;
                    }
                    let k = pos[j];
                    swap_positions(&mut collist, &mut pos, k, up);
                    up += 1;
                    dfix[j] = min;
                    d[j] = f64::NEG_INFINITY;
                }
            }
        }
        // Update the duals of the columns scanned ("ready").
        for &j in &collist[..last] {
            v[j] += dfix[j] - min;
        }
        // Augment along the alternating path.
        let mut j = endofpath;
        loop {
            let i = pred[j] as usize;
            y[j] = i;
            let next = x[i];
            x[i] = j;
            if i == freerow {
                break;
            }
            j = next;
        }
    }
    x
}

/// Exchanges the columns at positions `a` and `b` of `collist`, keeping
/// `pos` its inverse.
fn swap_positions(collist: &mut [usize], pos: &mut [usize], a: usize, b: usize) {
    collist.swap(a, b);
    pos[collist[a]] = a;
    pos[collist[b]] = b;
}

/// One scan of the shortest-path phase: for every column, the distance
/// through row `i` (reduced cost `ci[j] − v[j]` less `h`) replaces `d[j]`
/// and makes `i` the column's predecessor when it is lower. The columns
/// whose new distance equals `min` are left in `ties`, in column order.
/// Columns outside the todo part hold `d[j] = −∞` and are never lowered.
#[allow(clippy::too_many_arguments)]
fn scan_row(
    ci: &[f64],
    v: &[f64],
    h: f64,
    min: f64,
    i: f64,
    d: &mut [f64],
    pred: &mut [f64],
    ties: &mut Vec<usize>,
) {
    fn load(s: &[f64]) -> f64x4 {
        f64x4::from([s[0], s[1], s[2], s[3]])
    }
    ties.clear();
    let m = d.len();
    let split = m - m % 4;
    let (hw, minw, iw) = (f64x4::splat(h), f64x4::splat(min), f64x4::splat(i));
    let lanes = d[..split]
        .chunks_exact_mut(4)
        .zip(pred[..split].chunks_exact_mut(4))
        .zip(ci[..split].chunks_exact(4).zip(v[..split].chunks_exact(4)));
    for (c, ((dj, pj), (cj, vj))) in lanes.enumerate() {
        let dw = load(dj);
        let v2 = load(cj) - load(vj) - hw;
        let lower = v2.simd_lt(dw);
        dj.copy_from_slice(&lower.bitselect(v2, dw).to_array());
        pj.copy_from_slice(&lower.bitselect(iw, load(pj)).to_array());
        let mut at_min = (lower & v2.simd_eq(minw)).to_bitmask();
        while at_min != 0 {
            ties.push(4 * c + at_min.trailing_zeros() as usize);
            at_min &= at_min - 1;
        }
    }
    for j in split..m {
        let v2 = ci[j] - v[j] - h;
        if v2 < d[j] {
            d[j] = v2;
            pred[j] = i;
            if v2 == min {
                ties.push(j);
            }
        }
    }
}

/// The square initialisation: column reduction (each column's dual is its
/// cheapest cost, and the row of that cost takes it if it has no column
/// yet), then reduction transfer. Returns the rows left free.
fn column_reduction(
    n: usize,
    c: &[f64],
    x: &mut [usize],
    y: &mut [usize],
    v: &mut [f64],
) -> Vec<usize> {
    // Each column's minimum and its first row, found row by row (the
    // matrix is row-major: walking it by columns would miss the cache).
    let mut imin = vec![0usize; n];
    v.copy_from_slice(&c[..n]);
    for i in 1..n {
        let ci = &c[i * n..(i + 1) * n];
        // Branch-free, so that it compiles to vector selects.
        for ((vj, mj), cij) in v.iter_mut().zip(imin.iter_mut()).zip(ci) {
            let lower = *cij < *vj;
            *vj = if lower { *cij } else { *vj };
            *mj = if lower { i } else { *mj };
        }
    }
    let mut matches = vec![0u32; n];
    // Columns from the last: a row that is the cheapest of several columns
    // keeps the last of them; the other columns are free.
    for j in (0..n).rev() {
        let i = imin[j];
        matches[i] += 1;
        if matches[i] == 1 {
            x[i] = j;
            y[j] = i;
        }
    }

    // Reduction transfer.
    let mut free: Vec<usize> = Vec::with_capacity(n);
    for i in 0..n {
        if x[i] == NONE {
            free.push(i);
        } else if matches[i] == 1 {
            let j1 = x[i];
            let ci = &c[i * n..(i + 1) * n];
            let mut min = f64::INFINITY;
            for j in 0..n {
                if j != j1 {
                    let h = ci[j] - v[j];
                    if h < min {
                        min = h;
                    }
                }
            }
            if min.is_finite() {
                v[j1] -= min;
            }
        }
    }
    free
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Exhaustive minimum over all injective assignments (rows ≤ cols) or
    /// column fillings (rows > cols).
    fn brute(rows: usize, cols: usize, c: &[f64]) -> f64 {
        fn go(
            r: usize,
            rows: usize,
            cols: usize,
            c: &[f64],
            used: &mut Vec<bool>,
            skips: usize,
        ) -> f64 {
            if r == rows {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            if skips > 0 {
                best = go(r + 1, rows, cols, c, used, skips - 1);
            }
            for j in 0..cols {
                if !used[j] {
                    used[j] = true;
                    best = best.min(c[r * cols + j] + go(r + 1, rows, cols, c, used, skips));
                    used[j] = false;
                }
            }
            best
        }
        go(
            0,
            rows,
            cols,
            c,
            &mut vec![false; cols],
            rows.saturating_sub(cols),
        )
    }

    fn valid(rows: usize, cols: usize, s: &Solution) -> bool {
        let mut seen = vec![false; cols];
        let assigned = s.row_to_col.iter().flatten().count();
        s.row_to_col
            .iter()
            .flatten()
            .all(|j| !std::mem::replace(&mut seen[*j], true))
            && assigned == rows.min(cols)
    }

    #[test]
    fn small_known_instance() {
        let c = [4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0];
        let s = solve(3, 3, &c);
        assert_eq!(s.cost, 5.0);
        assert_eq!(s.row_to_col, vec![Some(1), Some(0), Some(2)]);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]
        /// Optimal on every small instance (n ≤ 7), square or rectangular,
        /// with ties (small integer costs) and negative costs.
        #[test]
        fn matches_brute_force(rows in 1usize..=7, cols in 1usize..=7, seed in proptest::collection::vec(-5i32..20, 49)) {
            let c: Vec<f64> = seed[..rows * cols].iter().map(|x| f64::from(*x)).collect();
            let s = solve(rows, cols, &c);
            prop_assert!(valid(rows, cols, &s), "{s:?}");
            let b = brute(rows, cols, &c);
            prop_assert!((s.cost - b).abs() < 1e-9, "lapjv {} brute {} on {rows}x{cols} {c:?}", s.cost, b);
        }

        #[test]
        fn optimal_with_real_costs(rows in 1usize..=6, cols in 1usize..=6, seed in proptest::collection::vec(0.0f64..1.0, 36)) {
            let c: Vec<f64> = seed[..rows * cols].to_vec();
            let s = solve(rows, cols, &c);
            prop_assert!(valid(rows, cols, &s));
            prop_assert!((s.cost - brute(rows, cols, &c)).abs() < 1e-9);
        }
    }

    /// Textbook Hungarian with potentials (O(n²m), rows ≤ cols), as an
    /// independent reference for instances too large for brute force.
    fn hungarian(rows: usize, cols: usize, c: &[f64]) -> f64 {
        let (n, m) = (rows, cols);
        let inf = f64::INFINITY;
        let mut u = vec![0.0; n + 1];
        let mut v = vec![0.0; m + 1];
        let mut p = vec![0usize; m + 1];
        let mut way = vec![0usize; m + 1];
        for i in 1..=n {
            p[0] = i;
            let mut j0 = 0;
            let mut minv = vec![inf; m + 1];
            let mut used = vec![false; m + 1];
            loop {
                used[j0] = true;
                let i0 = p[j0];
                let mut delta = inf;
                let mut j1 = 0;
                for j in 1..=m {
                    if !used[j] {
                        let cur = c[(i0 - 1) * m + (j - 1)] - u[i0] - v[j];
                        if cur < minv[j] {
                            minv[j] = cur;
                            way[j] = j0;
                        }
                        if minv[j] < delta {
                            delta = minv[j];
                            j1 = j;
                        }
                    }
                }
                for j in 0..=m {
                    if used[j] {
                        u[p[j]] += delta;
                        v[j] -= delta;
                    } else {
                        minv[j] -= delta;
                    }
                }
                j0 = j1;
                if p[j0] == 0 {
                    break;
                }
            }
            loop {
                let j1 = way[j0];
                p[j0] = p[j1];
                j0 = j1;
                if j0 == 0 {
                    break;
                }
            }
        }
        (1..=m)
            .filter(|j| p[*j] != 0)
            .map(|j| c[(p[j] - 1) * m + (j - 1)])
            .sum()
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]
        /// Larger instances, where the augmenting-path phase does the work,
        /// against the reference: random reals and tie-heavy small integers.
        #[test]
        fn matches_the_reference_on_larger_instances(
            n in 8usize..60, extra in 0usize..20, ties in any::<bool>(), seed in any::<u64>()
        ) {
            use rand::{RngExt, SeedableRng};
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let (rows, cols) = (n, n + extra);
            let c: Vec<f64> = (0..rows * cols)
                .map(|_| if ties { f64::from(rng.random_range(0..4u8)) } else { rng.random_range(0.0..100.0) })
                .collect();
            let s = solve(rows, cols, &c);
            prop_assert!(valid(rows, cols, &s));
            let h = hungarian(rows, cols, &c);
            prop_assert!((s.cost - h).abs() < 1e-6, "lapjv {} reference {}", s.cost, h);
        }
    }

    #[test]
    fn infinite_costs_are_avoided_when_possible() {
        let inf = f64::INFINITY;
        let c = [inf, 1.0, 2.0, inf];
        let s = solve(2, 2, &c);
        assert_eq!(s.row_to_col, vec![Some(1), Some(0)]);
        assert_eq!(s.cost, 3.0);
    }

    /// The transpose of a row-major `rows × cols` matrix.
    fn transpose(rows: usize, cols: usize, c: &[f64]) -> Vec<f64> {
        (0..cols)
            .flat_map(|j| (0..rows).map(move |i| c[i * cols + j]))
            .collect()
    }

    fn random_costs(rows: usize, cols: usize, kind: u8, seed: u64) -> Vec<f64> {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..rows * cols)
            .map(|_| match kind {
                0 => rng.random_range(0.0..100.0),
                1 => f64::from(rng.random_range(0..11u8)),
                2 => f64::from(rng.random_range(0..2u8)),
                _ => 5.0,
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]
        /// Rectangular both ways, tied and integer costs (0..10, 0..1,
        /// constant), small enough for brute force.
        #[test]
        fn rectangular_and_tied_match_brute_force(
            rows in 1usize..=8, cols in 1usize..=8, kind in 0u8..4, seed in any::<u64>()
        ) {
            let c = random_costs(rows, cols, kind, seed);
            let s = solve(rows, cols, &c);
            prop_assert!(valid(rows, cols, &s), "{s:?}");
            let b = brute(rows, cols, &c);
            prop_assert!((s.cost - b).abs() < 1e-9, "lapjv {} brute {} on {rows}x{cols} {c:?}", s.cost, b);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
        /// Larger rectangular problems, wide and tall (the latter against
        /// the reference on the transpose), on real, integer, 0/1 and
        /// constant costs; and the same matrix gives the same total
        /// whichever way round it is given.
        #[test]
        fn rectangular_matches_the_reference(
            short in 1usize..40, extra in 1usize..80, kind in 0u8..4, tall in any::<bool>(), seed in any::<u64>()
        ) {
            let (n, m) = (short, short + extra);
            let c = random_costs(n, m, kind, seed);
            let h = hungarian(n, m, &c);
            let s = if tall {
                let t = transpose(n, m, &c);
                let s = solve(m, n, &t);
                prop_assert!(valid(m, n, &s), "{s:?}");
                s
            } else {
                let s = solve(n, m, &c);
                prop_assert!(valid(n, m, &s), "{s:?}");
                s
            };
            prop_assert!((s.cost - h).abs() < 1e-6, "lapjv {} reference {} ({}x{}, tall {tall})", s.cost, h, n, m);
        }

        /// Square problems with heavy ties (where the row reduction's tie
        /// budget runs out), against the reference.
        #[test]
        fn tied_square_matches_the_reference(n in 60usize..140, kind in 1u8..4, seed in any::<u64>()) {
            let c = random_costs(n, n, kind, seed);
            let s = solve(n, n, &c);
            prop_assert!(valid(n, n, &s));
            prop_assert!((s.cost - hungarian(n, n, &c)).abs() < 1e-6);
        }
    }

    #[test]
    fn infinite_costs_are_avoided_in_rectangular_problems() {
        let inf = f64::INFINITY;
        // Wide: row 0 can only take column 2.
        let c = [inf, inf, 3.0, 1.0, 1.0, 1.0];
        let s = solve(2, 3, &c);
        assert_eq!(s.row_to_col[0], Some(2));
        assert_eq!(s.cost, 4.0);
        // Tall: column 1 only from row 2; a column nobody can take still
        // gets a row (the least bad).
        let c = [1.0, inf, 1.0, inf, inf, 2.0, inf, inf];
        let s = solve(4, 2, &c);
        assert_eq!(s.row_to_col[2], Some(1));
        assert_eq!(s.row_to_col.iter().flatten().count(), 2);
        assert_eq!(s.cost, 3.0);
        let s = solve(2, 2, &[f64::NAN, f64::NEG_INFINITY, 1.0, 1.0]);
        assert!(valid(2, 2, &s));
    }

    /// Square problems keep the assignment the solver always gave on ties
    /// while the tie budget lasts (the small teams of `alloc.optimal`).
    #[test]
    fn small_square_ties_keep_their_assignment() {
        // Constant 3 × 3, as `alloc.optimal` without utilities.
        let s = solve(3, 3, &[0.0; 9]);
        assert_eq!(s.row_to_col, vec![Some(2), Some(0), Some(1)]);
        let s = solve(10, 10, &[0.0; 100]);
        assert_eq!(
            s.row_to_col,
            [9, 0, 3, 4, 5, 6, 7, 8, 1, 2].map(Some).to_vec()
        );
    }

    /// Ties are broken as JV breaks them: on integer and 0/1 costs, where
    /// a scan often brings several columns to the minimum at once, the
    /// assignments are those the solver gave before its scans were
    /// vectorized (pinned as digests of `row_to_col`); `alloc.optimal`'s
    /// decisions rest on them.
    #[test]
    fn ties_are_broken_in_jv_order() {
        fn digest(s: &Solution) -> u64 {
            s.row_to_col.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, c| {
                (h ^ c.map_or(u64::MAX, |c| c as u64)).wrapping_mul(0x0100_0000_01b3)
            })
        }
        const PINNED: [u64; 48] = [
            1842648249690373234,
            14861152499044524960,
            13995931372903417408,
            10419956597383813502,
            18138117521441509518,
            10143854169240347294,
            13569316921194571878,
            2269537129870702084,
            9204149986513272003,
            11374246979008032963,
            10184707834160180855,
            6961663044338402221,
            13630384801331395577,
            214756100425418145,
            9052351088565217995,
            9773562332640350889,
            3290171024129675811,
            3630267156609124405,
            3290814696353811091,
            13055427834040671219,
            15711450720049523967,
            9167544491434968699,
            9164934464020811719,
            15121296951486742645,
            4593646963030219031,
            11756992454947545407,
            2674088766584693584,
            10116830150417392339,
            11139658718003630302,
            11644875093638510956,
            3747169809360713607,
            13401745706617570200,
            18426238576343895379,
            13240326990023753751,
            15387078547002725341,
            6918297360829777215,
            15220659360278216515,
            15483426308192746035,
            8793227833583400417,
            13997567712482913745,
            11063882493291746623,
            2023550463508977637,
            10875462996956211409,
            15707182259349038107,
            725282377096453931,
            14165557576743777617,
            17342600445804057,
            2038556667673521093,
        ];
        let cases = [(23, 23), (40, 40), (64, 64), (30, 47), (47, 30), (97, 97)];
        let mut got = Vec::new();
        for (rows, cols) in cases {
            for kind in [1u8, 2] {
                for seed in 0..4u64 {
                    let c = random_costs(rows, cols, kind, seed);
                    got.push(digest(&solve(rows, cols, &c)));
                }
            }
        }
        assert_eq!(got, PINNED);
    }
}
