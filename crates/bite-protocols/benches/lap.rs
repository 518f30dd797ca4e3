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
