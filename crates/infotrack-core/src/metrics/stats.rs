//! Small statistics: mean and sample standard deviation, median, Welch's t-test.

use statrs::distribution::{ContinuousCDF, StudentsT};

/// Mean and sample standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MeanSd {
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (n - 1); 0 for a single sample.
    pub sd: f64,
}

/// Mean and sample standard deviation of `x` (NaN mean for no samples).
pub fn mean_sd(x: &[f64]) -> MeanSd {
    let n = x.len();
    if n == 0 {
        return MeanSd {
            mean: f64::NAN,
            sd: f64::NAN,
        };
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let sd = if n > 1 {
        (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    } else {
        0.0
    };
    MeanSd { mean, sd }
}

/// Median (NaN for no samples).
pub fn median(x: &[f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    let mut v = x.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Welch's unequal-variance t-test.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct WelchResult {
    /// t statistic (mean a - mean b over the standard error).
    pub t: f64,
    /// Welch-Satterthwaite degrees of freedom.
    pub df: f64,
    /// Two-sided p-value.
    pub p_value: f64,
}

/// Welch's t-test of `a` against `b`; `None` with fewer than two samples on a side, or
/// when both have zero variance.
pub fn welch_t_test(a: &[f64], b: &[f64]) -> Option<WelchResult> {
    if a.len() < 2 || b.len() < 2 {
        return None;
    }
    let (ma, mb) = (mean_sd(a), mean_sd(b));
    let (va, vb) = (
        ma.sd * ma.sd / a.len() as f64,
        mb.sd * mb.sd / b.len() as f64,
    );
    let se2 = va + vb;
    if se2.is_nan() || se2 <= 0.0 {
        return None;
    }
    let t = (ma.mean - mb.mean) / se2.sqrt();
    let df = se2 * se2 / (va * va / (a.len() - 1) as f64 + vb * vb / (b.len() - 1) as f64);
    let dist = StudentsT::new(0.0, 1.0, df).ok()?;
    let p_value = 2.0 * (1.0 - dist.cdf(t.abs()));
    Some(WelchResult { t, df, p_value })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_sd_and_median_by_hand() {
        let m = mean_sd(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]);
        assert!((m.mean - 5.0).abs() < 1e-12);
        assert!((m.sd - (32.0f64 / 7.0).sqrt()).abs() < 1e-12);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    }

    #[test]
    fn welch_matches_a_textbook_value() {
        // Computed independently in Python (Welch formulas, t pdf integrated numerically):
        // t = -2.07401, df = 10.2092, p = 0.06428.
        let a = [19.8, 20.4, 19.6, 17.8, 18.5, 18.9, 18.3, 18.9, 19.5, 22.0];
        let b = [28.2, 26.6, 20.1, 23.3, 25.2, 22.1, 17.7, 27.6, 20.6, 13.7];
        let r = welch_t_test(&a, &b).unwrap();
        assert!((r.t - (-2.07401)).abs() < 1e-4, "{r:?}");
        assert!((r.df - 10.2092).abs() < 1e-3, "{r:?}");
        assert!((r.p_value - 0.06428).abs() < 1e-4, "{r:?}");
    }

    #[test]
    fn welch_needs_two_samples_a_side() {
        assert!(welch_t_test(&[1.0], &[1.0, 2.0]).is_none());
        assert!(welch_t_test(&[1.0, 1.0], &[1.0, 1.0]).is_none());
    }
}
