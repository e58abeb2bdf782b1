//! Paired statistics for runs that share their seeds (common random numbers: run i of every
//! guidance law chases the same target with the same noise), as SciPy 1.14 computes them:
//! the paired t-test with the mean difference's 95 % confidence interval and Cohen's d_z,
//! the Wilcoxon signed-rank test (`scipy.stats.wilcoxon` defaults: zeros dropped, exact
//! null distribution up to 50 pairs without zeros, else the normal approximation with the
//! tie correction and no continuity correction), and Holm's correction over a family of
//! tests. `tests/paired_stats_scipy.rs` checks them against SciPy itself.

use statrs::distribution::{ContinuousCDF, Normal, StudentsT};

/// The paired t-test of `a - b`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PairedT {
    /// Pairs.
    pub n: usize,
    /// Mean of the differences a - b.
    pub mean_diff: f64,
    /// Its 95 % confidence interval (t distribution), low and high.
    pub ci95: [f64; 2],
    /// t statistic.
    pub t: f64,
    /// Degrees of freedom, n - 1.
    pub df: f64,
    /// Two-sided p-value.
    pub p_value: f64,
    /// Effect size: the mean difference over the differences' standard deviation (d_z).
    pub cohen_dz: f64,
}

/// The paired t-test of `a` against `b` (same length, paired by index); `None` with fewer
/// than two pairs or differences without spread.
pub fn paired_t_test(a: &[f64], b: &[f64]) -> Option<PairedT> {
    let d = differences(a, b)?;
    let n = d.len();
    if n < 2 {
        return None;
    }
    let mean = d.iter().sum::<f64>() / n as f64;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    // Differences equal up to rounding have no spread to test against.
    if sd.is_nan() || sd <= 1e-12 * (1.0 + mean.abs()) {
        return None;
    }
    let se = sd / (n as f64).sqrt();
    let df = (n - 1) as f64;
    let dist = StudentsT::new(0.0, 1.0, df).ok()?;
    let t = mean / se;
    let half = dist.inverse_cdf(0.975) * se;
    Some(PairedT {
        n,
        mean_diff: mean,
        ci95: [mean - half, mean + half],
        t,
        df,
        p_value: 2.0 * dist.sf(t.abs()),
        cohen_dz: mean / sd,
    })
}

/// The Wilcoxon signed-rank test of `a - b`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Wilcoxon {
    /// Pairs with a non-zero difference (the others are dropped).
    pub n: usize,
    /// min(W+, W-), as SciPy reports it.
    pub statistic: f64,
    /// Two-sided p-value.
    pub p_value: f64,
    /// Whether the exact null distribution was used (else the normal approximation).
    pub exact: bool,
}

/// The Wilcoxon signed-rank test of `a` against `b` (paired by index); `None` without a
/// non-zero difference.
pub fn wilcoxon_signed_rank(a: &[f64], b: &[f64]) -> Option<Wilcoxon> {
    let d = differences(a, b)?;
    let has_zeros = d.contains(&0.0);
    let nonzero: Vec<f64> = d.iter().copied().filter(|x| *x != 0.0).collect();
    let count = nonzero.len();
    if count == 0 {
        return None;
    }
    let (ranks, ties) = average_ranks(&nonzero.iter().map(|x| x.abs()).collect::<Vec<_>>());
    let r_plus: f64 = nonzero
        .iter()
        .zip(&ranks)
        .filter(|(x, _)| **x > 0.0)
        .map(|(_, r)| r)
        .sum();
    let r_minus: f64 = nonzero
        .iter()
        .zip(&ranks)
        .filter(|(x, _)| **x < 0.0)
        .map(|(_, r)| r)
        .sum();
    let exact = d.len() <= 50 && !has_zeros;
    let p_value = if exact {
        exact_two_sided_p(count, r_plus)
    } else {
        let c = count as f64;
        let mn = c * (c + 1.0) * 0.25;
        let tie_correct: f64 = ties.iter().map(|t| t * t * t - t).sum();
        let se = ((c * (c + 1.0) * (2.0 * c + 1.0) - tie_correct / 2.0) / 24.0).sqrt();
        let z = (r_plus - mn) / se;
        let normal = Normal::new(0.0, 1.0).ok()?;
        2.0 * normal.sf(z.abs())
    };
    Some(Wilcoxon {
        n: count,
        statistic: r_plus.min(r_minus),
        p_value: p_value.min(1.0),
        exact,
    })
}

/// Holm's step-down adjustment of a family of p-values (same order as given).
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| p[i].total_cmp(&p[j]));
    let mut adjusted = vec![f64::NAN; m];
    let mut running = 0.0f64;
    for (k, &i) in order.iter().enumerate() {
        running = running.max(((m - k) as f64 * p[i]).min(1.0));
        adjusted[i] = running;
    }
    adjusted
}

/// `a - b`, or `None` if the lengths differ or a value is not finite.
fn differences(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    if a.len() != b.len() || a.iter().chain(b).any(|x| !x.is_finite()) {
        return None;
    }
    Some(a.iter().zip(b).map(|(x, y)| x - y).collect())
}

/// Ranks 1..n of `x` with ties given their average rank, and the sizes of the tie groups.
fn average_ranks(x: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|&i, &j| x[i].total_cmp(&x[j]));
    let mut ranks = vec![0.0; x.len()];
    let mut ties = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && x[order[end]] == x[order[start]] {
            end += 1;
        }
        let rank = 0.5 * ((start + 1) + end) as f64;
        for &i in &order[start..end] {
            ranks[i] = rank;
        }
        ties.push((end - start) as f64);
        start = end;
    }
    (ranks, ties)
}

/// The two-sided exact p-value of W+ = `r_plus` among `n` pairs: twice the smaller tail
/// (SciPy rounds a non-integral statistic outward), at most 1.
fn exact_two_sided_p(n: usize, r_plus: f64) -> f64 {
    // counts[k]: subsets of {1..n} whose sum is k.
    let max = n * (n + 1) / 2;
    let mut counts = vec![0.0f64; max + 1];
    counts[0] = 1.0;
    for r in 1..=n {
        for k in (r..=max).rev() {
            counts[k] += counts[k - r];
        }
    }
    let total = 2f64.powi(n as i32);
    let pmf: Vec<f64> = counts.iter().map(|c| c / total).collect();
    let upper = r_plus.floor().max(0.0) as usize;
    let lower = (r_plus.ceil().max(0.0) as usize).min(max);
    let sf: f64 = pmf[upper.min(max + 1)..].iter().sum();
    let cdf: f64 = pmf[..=lower].iter().sum();
    (2.0 * sf.min(cdf)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_wilcoxon_by_hand() {
        // Five positive differences: W+ = 15, the most extreme of 2^5 sign patterns on
        // either side: p = 2 / 32.
        let w = wilcoxon_signed_rank(&[1.0, 2.0, 3.0, 4.0, 5.0], &[0.0; 5]).unwrap();
        assert!(w.exact);
        assert_eq!(w.statistic, 0.0);
        assert!((w.p_value - 2.0 / 32.0).abs() < 1e-15);
    }

    #[test]
    fn holm_by_hand() {
        let adj = holm(&[0.01, 0.04, 0.03]);
        for (got, want) in adj.iter().zip([0.03, 0.06, 0.06]) {
            assert!((got - want).abs() < 1e-15, "{adj:?}");
        }
    }

    #[test]
    fn nothing_to_test_is_none() {
        assert!(paired_t_test(&[1.0], &[2.0]).is_none());
        assert!(paired_t_test(&[1.0, 2.0], &[0.0, 1.0]).is_none());
        assert!(wilcoxon_signed_rank(&[1.0, 2.0], &[1.0, 2.0]).is_none());
        assert!(wilcoxon_signed_rank(&[1.0, 2.0], &[1.0]).is_none());
    }
}
