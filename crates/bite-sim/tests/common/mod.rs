//! What the simulator's property tests share.

use proptest::test_runner::{Config, RngSeed};

/// `cases` cases (or `PROPTEST_CASES`), the same ones on every run, CI
/// included, unless `PROPTEST_RNG_SEED` asks for others
/// (`PROPTEST_RNG_SEED=$RANDOM PROPTEST_CASES=3000` to explore).
pub fn config(cases: u32) -> Config {
    let base = Config::default();
    Config {
        cases: std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|c| c.parse().ok())
            .unwrap_or(cases),
        failure_persistence: None,
        rng_seed: match base.rng_seed {
            RngSeed::Random => RngSeed::Fixed(0xB17E),
            chosen => chosen,
        },
        ..base
    }
}
