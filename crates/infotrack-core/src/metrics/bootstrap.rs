//! The bootstrap confidence interval of a mean, bias-corrected and accelerated (BCa, Efron
//! 1987), as `scipy.stats.bootstrap` computes it by default: resample with replacement,
//! correct the percentiles for the resampled means' median bias (z0) and for how the
//! standard error changes with the mean (the jackknife's acceleration a), and read the
//! corrected percentiles off the resampled means with linear interpolation (NumPy's
//! default). A mean of ten or so Monte Carlo runs of a skewed metric (%FOV piles up at 0
//! and 100) is not normal; the BCa interval follows the skew where a t interval cannot.
//! `tests/paired_stats_scipy.rs` compares it with SciPy's on the same numbers.

use rand::Rng;
use statrs::distribution::{ContinuousCDF, Normal};

/// Resamples drawn for one interval: SciPy's default, and enough that the interval's ends
/// move by well under 1 % of its width from one seed to another.
pub const RESAMPLES: usize = 10_000;

/// The 95 % BCa bootstrap interval of the mean of `x` from `resamples` resamples drawn
/// with `rng`; `None` with fewer than two values or one that is not finite. Values without
/// spread give the point interval at their mean.
pub fn bca_mean_ci95(x: &[f64], resamples: usize, rng: &mut impl Rng) -> Option<[f64; 2]> {
    let n = x.len();
    if n < 2 || resamples < 2 || x.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    if x.iter()
        .all(|v| (v - x[0]).abs() <= 1e-12 * (1.0 + v.abs()))
    {
        return Some([mean, mean]);
    }
    let mut means: Vec<f64> = (0..resamples)
        .map(|_| (0..n).map(|_| x[rng.gen_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(|a, b| a.total_cmp(b));
    let [lo, hi] = bca_levels(x, mean, &means)?;
    Some([percentile_linear(&means, lo), percentile_linear(&means, hi)])
}

/// The BCa-corrected lower and upper levels (fractions in 0..1) for a 95 % interval.
fn bca_levels(x: &[f64], mean: f64, sorted_means: &[f64]) -> Option<[f64; 2]> {
    let normal = Normal::new(0.0, 1.0).ok()?;
    // The mean's mid-rank among the resampled means (SciPy's `_percentile_of_score`): the
    // means of a few discrete values tie with it often, and counting ties as half keeps z0
    // unbiased there.
    let below = sorted_means.iter().filter(|m| **m < mean).count();
    let at_or_below = sorted_means.iter().filter(|m| **m <= mean).count();
    let rank = (below + at_or_below) as f64 / (2 * sorted_means.len()) as f64;
    let z0 = normal.inverse_cdf(rank);
    let a = jackknife_acceleration(x);
    let level = |alpha: f64| {
        let z = normal.inverse_cdf(alpha);
        normal.cdf(z0 + (z0 + z) / (1.0 - a * (z0 + z)))
    };
    let levels = [level(0.025), level(0.975)];
    // All resamples on one side of the mean (a tiny or lopsided sample): no correction can
    // be estimated, as SciPy warns; fall back to the plain percentiles.
    if levels.iter().all(|l| l.is_finite()) {
        Some(levels)
    } else {
        Some([0.025, 0.975])
    }
}

/// The acceleration from the leave-one-out means: the skewness of their spread over six.
fn jackknife_acceleration(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let total: f64 = x.iter().sum();
    let loo: Vec<f64> = x.iter().map(|v| (total - v) / (n - 1.0)).collect();
    let loo_mean = loo.iter().sum::<f64>() / n;
    let num: f64 = loo.iter().map(|t| (loo_mean - t).powi(3)).sum();
    let den: f64 = loo.iter().map(|t| (loo_mean - t).powi(2)).sum::<f64>();
    if den <= 0.0 {
        return 0.0;
    }
    num / (6.0 * den.powf(1.5))
}

/// The `level` (0..1) quantile of sorted values with linear interpolation between the two
/// nearest order statistics (NumPy's `percentile` default).
fn percentile_linear(sorted: &[f64], level: f64) -> f64 {
    let pos = level.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let i = pos.floor() as usize;
    let j = (i + 1).min(sorted.len() - 1);
    sorted[i] + (pos - i as f64) * (sorted[j] - sorted[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{stream_rng, Stream};

    fn rng(seed: u64) -> crate::rng::CoreRng {
        stream_rng(seed, 0, Stream::Statistics, 0)
    }

    #[test]
    fn the_interval_holds_the_mean_and_the_same_seed_gives_the_same_interval() {
        let x = [81.2, 77.5, 90.1, 65.3, 88.8, 72.0, 12.0, 99.0];
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let a = bca_mean_ci95(&x, RESAMPLES, &mut rng(1)).unwrap();
        let b = bca_mean_ci95(&x, RESAMPLES, &mut rng(1)).unwrap();
        assert_eq!(a, b);
        assert!(a[0] < mean && mean < a[1], "{a:?} around {mean}");
    }

    #[test]
    fn a_larger_sample_of_the_same_spread_gives_a_narrower_interval() {
        let small: Vec<f64> = (0..10).map(|i| (i * 37 % 11) as f64).collect();
        let large: Vec<f64> = (0..160).map(|i| (i * 37 % 11) as f64).collect();
        let s = bca_mean_ci95(&small, RESAMPLES, &mut rng(2)).unwrap();
        let l = bca_mean_ci95(&large, RESAMPLES, &mut rng(2)).unwrap();
        // sqrt(16) = 4 times narrower, within resampling noise.
        let ratio = (s[1] - s[0]) / (l[1] - l[0]);
        assert!((3.0..5.0).contains(&ratio), "width ratio {ratio}");
    }

    #[test]
    fn values_without_spread_give_a_point_and_too_few_or_bad_values_none() {
        assert_eq!(
            bca_mean_ci95(&[3.0; 5], RESAMPLES, &mut rng(3)),
            Some([3.0, 3.0])
        );
        assert_eq!(bca_mean_ci95(&[3.0], RESAMPLES, &mut rng(3)), None);
        assert_eq!(
            bca_mean_ci95(&[1.0, f64::NAN], RESAMPLES, &mut rng(3)),
            None
        );
    }

    #[test]
    fn linear_percentiles_interpolate_between_order_statistics() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(percentile_linear(&v, 0.0), 1.0);
        assert_eq!(percentile_linear(&v, 0.5), 3.0);
        assert_eq!(percentile_linear(&v, 0.125), 1.5);
        assert_eq!(percentile_linear(&v, 1.0), 5.0);
    }
}
