//! `alloc.optimal`'s solver on random uniform costs, n × n.
//! Goal: 1,000 × 1,000 in ≤ 100 ms.

use bite_protocols::lap::solve;
use rand::{RngExt, SeedableRng};

fn main() {
    divan::main();
}

#[divan::bench(args = [10, 100, 1000])]
fn lapjv_random(b: divan::Bencher, n: usize) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let c: Vec<f64> = (0..n * n).map(|_| rng.random_range(0.0..1000.0)).collect();
    b.bench_local(|| divan::black_box(solve(n, n, divan::black_box(&c))));
}

/// Robots and tasks at random points of a 100 m square, cost = distance
/// (what `bite bench protocols --large` allocates): many near-ties, the
/// hard case for the augmenting row reduction.
#[divan::bench(args = [10, 100, 1000])]
fn lapjv_euclidean(b: divan::Bencher, n: usize) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let mut pt = || [rng.random_range(0.0..100.0), rng.random_range(0.0..100.0)];
    let robots: Vec<[f64; 2]> = (0..n).map(|_| pt()).collect();
    let tasks: Vec<[f64; 2]> = (0..n).map(|_| pt()).collect();
    let c: Vec<f64> = robots
        .iter()
        .flat_map(|r| {
            tasks
                .iter()
                .map(move |t| ((r[0] - t[0]).powi(2) + (r[1] - t[1]).powi(2)).sqrt() - 150.0)
        })
        .collect();
    b.bench_local(|| divan::black_box(solve(n, n, divan::black_box(&c))));
}
