//! `alloc.optimal`'s solver: random uniform costs and distances n × n,
//! tie-heavy integer and constant costs, rectangular problems both ways.
//! Goal: 1,000 × 1,000 in ≤ 100 ms; SciPy's times on the same kinds of
//! matrix are in `docs/performance.md` (`scripts/lap_vs_scipy.py`).

use bite_protocols::lap::solve;
use rand::{RngExt, SeedableRng};

// The allocator the `bite` binary runs with, so that the figures are its.
#[global_allocator]
static ALLOC: bite_alloc::MiMalloc = bite_alloc::MiMalloc;

fn main() {
    divan::main();
}

fn uniform(rows: usize, cols: usize) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    (0..rows * cols)
        .map(|_| rng.random_range(0.0..1000.0))
        .collect()
}

/// Robots and tasks at random points of a 100 m square, cost = distance
/// (what `bite bench protocols --large` allocates): many near-ties, the
/// hard case for the augmenting row reduction.
fn distances(rows: usize, cols: usize) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let mut pt = || [rng.random_range(0.0..100.0), rng.random_range(0.0..100.0)];
    let robots: Vec<[f64; 2]> = (0..rows).map(|_| pt()).collect();
    let tasks: Vec<[f64; 2]> = (0..cols).map(|_| pt()).collect();
    robots
        .iter()
        .flat_map(|r| {
            tasks
                .iter()
                .map(move |t| ((r[0] - t[0]).powi(2) + (r[1] - t[1]).powi(2)).sqrt() - 150.0)
        })
        .collect()
}

/// Integers 0..=10: ties everywhere.
fn integers(rows: usize, cols: usize) -> Vec<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    (0..rows * cols)
        .map(|_| f64::from(rng.random_range(0..=10u8)))
        .collect()
}

#[divan::bench(args = [10, 100, 1000])]
fn lapjv_random(b: divan::Bencher, n: usize) {
    let c = uniform(n, n);
    b.bench_local(|| divan::black_box(solve(n, n, divan::black_box(&c))));
}

#[divan::bench(args = [10, 100, 1000])]
fn lapjv_euclidean(b: divan::Bencher, n: usize) {
    let c = distances(n, n);
    b.bench_local(|| divan::black_box(solve(n, n, divan::black_box(&c))));
}

#[divan::bench(args = [100, 1000])]
fn lapjv_integers(b: divan::Bencher, n: usize) {
    let c = integers(n, n);
    b.bench_local(|| divan::black_box(solve(n, n, divan::black_box(&c))));
}

/// Every cost the same (`alloc.optimal` without utilities).
#[divan::bench(args = [100, 1000])]
fn lapjv_constant(b: divan::Bencher, n: usize) {
    let c = vec![7.0; n * n];
    b.bench_local(|| divan::black_box(solve(n, n, divan::black_box(&c))));
}

/// Rows × columns: fewer robots than places (300 × 1,000), and more
/// (1,000 × 300, solved on the transpose).
const SHAPES: [(usize, usize); 2] = [(300, 1000), (1000, 300)];

#[divan::bench(args = SHAPES)]
fn rectangular_random(b: divan::Bencher, (rows, cols): (usize, usize)) {
    let c = uniform(rows, cols);
    b.bench_local(|| divan::black_box(solve(rows, cols, divan::black_box(&c))));
}

#[divan::bench(args = SHAPES)]
fn rectangular_euclidean(b: divan::Bencher, (rows, cols): (usize, usize)) {
    let c = distances(rows, cols);
    b.bench_local(|| divan::black_box(solve(rows, cols, divan::black_box(&c))));
}

#[divan::bench(args = SHAPES)]
fn rectangular_integers(b: divan::Bencher, (rows, cols): (usize, usize)) {
    let c = integers(rows, cols);
    b.bench_local(|| divan::black_box(solve(rows, cols, divan::black_box(&c))));
}
