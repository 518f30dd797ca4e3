//! The statistics of `bite experiment` and `bite tune`: descriptive figures
//! with a 95 % confidence interval of the mean (Student's t), bootstrap
//! confidence intervals of differences, the Mann–Whitney rank test, and
//! Spearman's rank correlation.
//!
//! Every resampling draws from a generator seeded by its caller, so a
//! report is the same on every machine and for any thread count.

use bite_core::interaction::Rng;
use rand::{RngExt, SeedableRng};
use statrs::distribution::{ContinuousCDF, Normal, StudentsT};

/// Descriptive figures of a sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Describe {
    /// Sample size.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Standard deviation (n − 1).
    pub sd: f64,
    /// Half-width of the 95 % confidence interval of the mean (Student's
    /// t; 0 for fewer than two values).
    pub ci95: f64,
    /// Median.
    pub median: f64,
    /// First quartile.
    pub q1: f64,
    /// Third quartile.
    pub q3: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}

/// The `q`-quantile (0–1) of sorted values, by linear interpolation
/// between closest ranks (the usual "type 7" definition).
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let h = (n - 1) as f64 * q.clamp(0.0, 1.0);
            let lo = h.floor() as usize;
            let hi = (lo + 1).min(n - 1);
            sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
        }
    }
}

/// The two-sided 95 % critical value of Student's t with `df` degrees of
/// freedom.
pub fn t95(df: usize) -> f64 {
    match StudentsT::new(0.0, 1.0, df.max(1) as f64) {
        Ok(t) => t.inverse_cdf(0.975),
        Err(_) => 1.96,
    }
}

/// Describe a sample (NaN values are left out).
pub fn describe(values: &[f64]) -> Describe {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return Describe {
            mean: f64::NAN,
            median: f64::NAN,
            q1: f64::NAN,
            q3: f64::NAN,
            min: f64::NAN,
            max: f64::NAN,
            sd: f64::NAN,
            ..Describe::default()
        };
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    let sd = if n > 1 {
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    } else {
        0.0
    };
    let ci95 = if n > 1 {
        t95(n - 1) * sd / (n as f64).sqrt()
    } else {
        0.0
    };
    Describe {
        n,
        mean,
        sd,
        ci95,
        median: quantile(&v, 0.5),
        q1: quantile(&v, 0.25),
        q3: quantile(&v, 0.75),
        min: v[0],
        max: v[n - 1],
    }
}

/// A 95 % percentile-bootstrap confidence interval of `mean(b) − mean(a)`
/// (independent samples, `resamples` draws, seeded).
pub fn bootstrap_diff(a: &[f64], b: &[f64], resamples: usize, seed: u64) -> (f64, f64) {
    if a.is_empty() || b.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = Rng::seed_from_u64(seed);
    let mean_of = |x: &[f64], rng: &mut Rng| {
        let n = x.len();
        (0..n).map(|_| x[rng.random_range(0..n)]).sum::<f64>() / n as f64
    };
    let mut d: Vec<f64> = (0..resamples.max(1))
        .map(|_| mean_of(b, &mut rng) - mean_of(a, &mut rng))
        .collect();
    d.sort_by(f64::total_cmp);
    (quantile(&d, 0.025), quantile(&d, 0.975))
}

/// Ranks (1-based, ties get their mean rank) of values.
fn ranks(values: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..values.len()).collect();
    idx.sort_by(|&i, &j| values[i].total_cmp(&values[j]));
    let mut r = vec![0.0; values.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && values[idx[j + 1]] == values[idx[i]] {
            j += 1;
        }
        let mean_rank = (i + j) as f64 / 2.0 + 1.0;
        for k in &idx[i..=j] {
            r[*k] = mean_rank;
        }
        i = j + 1;
    }
    r
}

/// The two-sided p-value of the Mann–Whitney U test (normal
/// approximation with tie correction and continuity correction). 1 when
/// either sample is empty or every value is tied.
pub fn mann_whitney(a: &[f64], b: &[f64]) -> f64 {
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    if a.is_empty() || b.is_empty() {
        return 1.0;
    }
    let all: Vec<f64> = a.iter().chain(b).copied().collect();
    let r = ranks(&all);
    let r1: f64 = r[..a.len()].iter().sum();
    let u1 = r1 - n1 * (n1 + 1.0) / 2.0;
    let mu = n1 * n2 / 2.0;
    // Tie correction: Σ (t³ − t) over groups of ties.
    let mut sorted = all.clone();
    sorted.sort_by(f64::total_cmp);
    let mut ties = 0.0;
    let mut i = 0;
    while i < sorted.len() {
        let mut j = i;
        while j + 1 < sorted.len() && sorted[j + 1] == sorted[i] {
            j += 1;
        }
        let t = (j - i + 1) as f64;
        ties += t * t * t - t;
        i = j + 1;
    }
    let n = n1 + n2;
    let var = n1 * n2 / 12.0 * ((n + 1.0) - ties / (n * (n - 1.0)));
    if var <= 0.0 {
        return 1.0;
    }
    let z = ((u1 - mu).abs() - 0.5).max(0.0) / var.sqrt();
    let normal = Normal::standard();
    (2.0 * (1.0 - normal.cdf(z))).min(1.0)
}

/// Holm–Bonferroni adjusted p-values (same order as given): the family
/// of comparisons keeps a 5 % error rate when adjusted p < 0.05.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut idx: Vec<usize> = (0..m).collect();
    idx.sort_by(|&a, &b| p[a].total_cmp(&p[b]).then(a.cmp(&b)));
    let mut out = vec![0.0; m];
    let mut running: f64 = 0.0;
    for (rank, &i) in idx.iter().enumerate() {
        let adj = ((m - rank) as f64 * p[i]).min(1.0);
        running = running.max(adj);
        out[i] = running;
    }
    out
}

/// Spearman's rank correlation of paired values (NaN for fewer than three
/// pairs or a constant side).
pub fn spearman(x: &[f64], y: &[f64]) -> f64 {
    if x.len() != y.len() || x.len() < 3 {
        return f64::NAN;
    }
    let (rx, ry) = (ranks(x), ranks(y));
    pearson(&rx, &ry)
}

fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let mut sxy = 0.0;
    let mut sxx = 0.0;
    let mut syy = 0.0;
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx).powi(2);
        syy += (b - my).powi(2);
    }
    if sxx == 0.0 || syy == 0.0 {
        f64::NAN
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

/// The comparison of two samples (`b` against `a`).
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// `mean(b) − mean(a)`.
    pub diff: f64,
    /// Its 95 % bootstrap confidence interval.
    pub ci: (f64, f64),
    /// Mann–Whitney two-sided p-value.
    pub p: f64,
    /// The fewest seeds per side (the first n of each, in seed order) from
    /// which on the bootstrap interval excludes 0 and keeps excluding it
    /// with every seed added; `None` if it never does.
    pub seeds_needed: Option<usize>,
}

/// Compare `b` with `a` (values in seed order).
pub fn compare(a: &[f64], b: &[f64], seed: u64) -> Comparison {
    const RESAMPLES: usize = 2000;
    let ci = bootstrap_diff(a, b, RESAMPLES, seed);
    let excludes = |ci: (f64, f64)| ci.0 > 0.0 || ci.1 < 0.0;
    let mut needed = None;
    let n = a.len().min(b.len());
    // From the largest prefix down: the smallest n such that every prefix
    // from n up to the whole sample excludes 0.
    for k in (2..=n).rev() {
        let ci_k = if k == n && a.len() == b.len() {
            ci
        } else {
            bootstrap_diff(&a[..k], &b[..k], RESAMPLES, seed)
        };
        if excludes(ci_k) {
            needed = Some(k);
        } else {
            break;
        }
    }
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
    Comparison {
        diff: mean(b) - mean(a),
        ci,
        p: mann_whitney(a, b),
        seeds_needed: if excludes(ci) { needed } else { None },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_ranks() {
        let v = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile(&v, 0.5), 2.5);
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 1.0), 4.0);
        assert_eq!(quantile(&v, 0.25), 1.75);
    }

    #[test]
    fn the_confidence_interval_of_the_mean_uses_students_t() {
        // Five values: mean 3, sd √2.5; t(4, 0.975) = 2.776.
        let d = describe(&[1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(d.n, 5);
        assert!((d.mean - 3.0).abs() < 1e-12);
        assert!((d.sd - 2.5f64.sqrt()).abs() < 1e-12);
        assert!((t95(4) - 2.776).abs() < 1e-3, "{}", t95(4));
        assert!((d.ci95 - 2.776 * 2.5f64.sqrt() / 5f64.sqrt()).abs() < 1e-3);
        assert_eq!(describe(&[7.0]).ci95, 0.0);
    }

    #[test]
    fn mann_whitney_matches_a_worked_example() {
        // Fully separated samples of 5: U = 0, mean 12.5, variance
        // 5·5·11/12 = 22.92, z = (12.5 − 0.5)/4.787 = 2.507, p = 0.0122
        // (normal approximation, continuity corrected; the exact p is 0.0079).
        let a = [1.0, 2.0, 3.0, 4.0, 5.0];
        let b = [6.0, 7.0, 8.0, 9.0, 10.0];
        let p = mann_whitney(&a, &b);
        assert!((p - 0.0122).abs() < 2e-4, "p = {p}");
        assert_eq!(mann_whitney(&a, &a), 1.0);
        assert_eq!(mann_whitney(&[2.0, 2.0], &[2.0, 2.0]), 1.0);
    }

    #[test]
    fn holm_adjusts_in_order_and_stays_monotone() {
        let adj = holm(&[0.01, 0.04, 0.03, 0.5]);
        assert_eq!(adj, vec![0.04, 0.09, 0.09, 0.5]);
    }

    #[test]
    fn spearman_sees_monotone_relations() {
        let x = [1.0, 2.0, 3.0, 4.0];
        assert!((spearman(&x, &[10.0, 20.0, 35.0, 90.0]) - 1.0).abs() < 1e-12);
        assert!((spearman(&x, &[9.0, 5.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        assert!(spearman(&x, &[1.0, 1.0, 1.0, 1.0]).is_nan());
    }

    #[test]
    fn comparisons_find_real_differences_and_not_noise() {
        let a: Vec<f64> = (0..30).map(|i| 50.0 + (i % 7) as f64).collect();
        let b: Vec<f64> = (0..30).map(|i| 60.0 + (i % 5) as f64).collect();
        let c = compare(&a, &b, 1);
        assert!(c.diff > 8.0 && c.ci.0 > 0.0, "{c:?}");
        assert!(c.p < 1e-6);
        let n = c.seeds_needed.expect("a 10 s difference is found");
        assert!((2..=5).contains(&n), "{n}");
        // The same sample against itself: no difference.
        let same = compare(&a, &a, 1);
        assert!(same.ci.0 <= 0.0 && same.ci.1 >= 0.0);
        assert_eq!(same.seeds_needed, None);
        // Seeded: the same call gives the same interval.
        assert_eq!(compare(&a, &b, 1), c);
    }
}
