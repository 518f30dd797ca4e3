//! The linear assignment problem: Jonker-Volgenant (LAPJV).
//!
//! R. Jonker and A. Volgenant, *A shortest augmenting path algorithm for
//! dense and sparse linear assignment problems*, Computing 38 (1987). The
//! phases are column reduction, reduction transfer, two rounds of
//! augmenting row reduction (which assign most rows cheaply), then a
//! Dijkstra-like shortest augmenting path for each row still free. Dense,
//! `O(n³)` worst case, far faster on typical instances (1,000 × 1,000
//! random costs: see `docs/performance.md`).
//!
//! Rectangular problems are solved by padding to a square with zero-cost
//! dummy rows or columns.

// The algorithm walks parallel arrays (costs, duals, row and column
// assignments) by index; iterator rewrites would obscure it.
#![allow(clippy::needless_range_loop)]

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
    let finite_max = cost
        .iter()
        .filter(|c| c.is_finite())
        .fold(0.0f64, |m, c| m.max(c.abs()));
    let big = (finite_max + 1.0) * (n as f64 + 1.0);
    let mut c = vec![0.0f64; n * n];
    for i in 0..rows {
        for j in 0..cols {
            let v = cost[i * cols + j];
            c[i * n + j] = if v.is_finite() { v } else { big };
        }
    }
    let x = lapjv(n, &c);
    let row_to_col: Vec<Option<usize>> = (0..rows)
        .map(|i| x.get(i).copied().filter(|j| *j < cols))
        .collect();
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

/// Square LAPJV on an `n × n` row-major matrix; returns the column of each row.
fn lapjv(n: usize, c: &[f64]) -> Vec<usize> {
    let cost = |i: usize, j: usize| c[i * n + j];
    let mut x = vec![NONE; n]; // row -> column
    let mut y = vec![NONE; n]; // column -> row
    let mut v = vec![0.0f64; n]; // column duals
    let mut matches = vec![0u32; n];

    // Column reduction: each column's cheapest row.
    for j in (0..n).rev() {
        let mut imin = 0;
        let mut min = cost(0, j);
        for i in 1..n {
            if cost(i, j) < min {
                min = cost(i, j);
                imin = i;
            }
        }
        v[j] = min;
        matches[imin] += 1;
        if matches[imin] == 1 {
            x[imin] = j;
            y[j] = imin;
        } else {
            y[j] = NONE;
        }
    }
    // A row that is the cheapest of several columns keeps the first one
    // (x was set only when matches reached 1); the other columns are free.

    // Reduction transfer.
    let mut free: Vec<usize> = Vec::with_capacity(n);
    for i in 0..n {
        if x[i] == NONE {
            free.push(i);
        } else if matches[i] == 1 {
            let j1 = x[i];
            let mut min = f64::INFINITY;
            for j in 0..n {
                if j != j1 {
                    let h = cost(i, j) - v[j];
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

    // Augmenting row reduction, twice.
    for _ in 0..2 {
        let mut k = 0;
        let prv: Vec<usize> = std::mem::take(&mut free);
        let mut current = prv;
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
            let (mut umin, mut j1) = (cost(i, 0) - v[0], 0);
            let (mut usubmin, mut j2) = (f64::INFINITY, NONE);
            for j in 1..n {
                let h = cost(i, j) - v[j];
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
    let mut d = vec![0.0f64; n];
    let mut pred = vec![0usize; n];
    let mut collist = vec![0usize; n];
    for &freerow in &free {
        if x[freerow] != NONE {
            continue;
        }
        for j in 0..n {
            d[j] = cost(freerow, j) - v[j];
            pred[j] = freerow;
            collist[j] = j;
        }
        let (mut low, mut up) = (0usize, 0usize);
        let mut last = 0usize;
        let mut min = 0.0f64;
        let mut endofpath = NONE;
        while endofpath == NONE {
            if up == low {
                // Collect the columns at the new minimum distance. The scan
                // starts where `up` was; moving `up` inside is intended.
                last = low;
                min = d[collist[up]];
                up += 1;
                #[allow(clippy::mut_range_bound)]
                for k in up..n {
                    let j = collist[k];
                    let h = d[j];
                    if h <= min {
                        if h < min {
                            up = low;
                            min = h;
                        }
                        collist[k] = collist[up];
                        collist[up] = j;
                        up += 1;
                    }
                }
                for &j in &collist[low..up] {
                    if y[j] == NONE {
                        endofpath = j;
                        break;
                    }
                }
            }
            if endofpath == NONE {
                // Scan one column of the minimum set.
                let j1 = collist[low];
                low += 1;
                let i = y[j1];
                let h = cost(i, j1) - v[j1] - min;
                let mut k = up;
                while k < n {
                    let j = collist[k];
                    let v2 = cost(i, j) - v[j] - h;
                    if v2 < d[j] {
                        pred[j] = i;
                        if v2 == min {
                            if y[j] == NONE {
                                endofpath = j;
                                break;
                            }
                            collist[k] = collist[up];
                            collist[up] = j;
                            up += 1;
                        }
                        d[j] = v2;
                    }
                    k += 1;
                }
            }
        }
        // Update the duals of the columns scanned ("ready").
        for &j in &collist[..last] {
            v[j] += d[j] - min;
        }
        // Augment along the alternating path.
        let mut j = endofpath;
        loop {
            let i = pred[j];
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
}
