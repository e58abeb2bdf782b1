//! The paper's four metrics, per step and per run, and the statistics that compare methods.

pub mod bootstrap;
pub mod csv;
pub mod paired;
pub mod stats;

use nalgebra::Matrix2;

use crate::world::geometry::Enu2;
pub use stats::{mean_sd, median, welch_t_test, MeanSd, WelchResult};

/// What happened at one filter step.
#[derive(Debug, Clone)]
pub struct StepRecord {
    /// Time since the start, s.
    pub t_s: f64,
    /// True target position, world ENU.
    pub target_enu: Enu2,
    /// Agent position, world ENU.
    pub agent_enu: Enu2,
    /// Setpoint the agent was flying to, world ENU.
    pub waypoint_enu: Enu2,
    /// The measurement, if the target was seen.
    pub measurement_enu: Option<Enu2>,
    /// The estimate (weighted mean or KF mean), world ENU.
    pub estimate_enu: Enu2,
    /// Its covariance, m^2.
    pub cov_m2: Matrix2<f64>,
    /// N_eff of the particle filter (NaN for the Kalman filter).
    pub n_eff: f64,
    /// EER of the current waypoint (NaN for other laws).
    pub eer: f64,
    /// Whether the target was inside an occlusion.
    pub target_occluded: bool,
    /// Whether the target was inside the camera footprint.
    pub target_in_footprint: bool,
}

impl StepRecord {
    /// e = |s_k - x_k|.
    pub fn tracking_error_m(&self) -> f64 {
        (self.agent_enu - self.target_enu).norm()
    }
    /// e~ = |mu_k - x_k|.
    pub fn estimation_error_m(&self) -> f64 {
        (self.estimate_enu - self.target_enu).norm()
    }
    /// det(Sigma_k).
    pub fn cov_det(&self) -> f64 {
        self.cov_m2.determinant()
    }
}

/// One run's metrics: means over its steps, and timing medians. Read back from JSON (a
/// campaign's shards are merged from theirs), where a figure that could not be measured
/// (NaN) was written as `null`.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct RunSummary {
    /// Mean tracking error, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub tracking_error_m: f64,
    /// Mean estimation error, m.
    #[serde(deserialize_with = "nan_if_null")]
    pub estimation_error_m: f64,
    /// Mean det of the covariance, m^4.
    #[serde(deserialize_with = "nan_if_null")]
    pub cov_det: f64,
    /// Share of steps with a measurement, percent.
    #[serde(deserialize_with = "nan_if_null")]
    pub fov_percent: f64,
    /// Median filter step time, ms.
    #[serde(deserialize_with = "nan_if_null")]
    pub filter_step_ms: f64,
    /// Median guidance step time, ms.
    #[serde(deserialize_with = "nan_if_null")]
    pub guidance_step_ms: f64,
    /// When the target was first measured, s since the start (the search's length); `None`
    /// when it never was.
    pub first_sighting_s: Option<f64>,
    /// Mean tracking error from the first sighting on, m (the tracking apart from the
    /// search); `None` when the target was never seen.
    pub tracking_error_after_first_sighting_m: Option<f64>,
}

impl RunSummary {
    /// From a run's step records and timings.
    pub fn from_steps(steps: &[StepRecord], filter_ms: &[f64], guidance_ms: &[f64]) -> Self {
        let first = steps.iter().position(|s| s.measurement_enu.is_some());
        Self {
            tracking_error_m: mean_over(steps, StepRecord::tracking_error_m),
            estimation_error_m: mean_over(steps, StepRecord::estimation_error_m),
            cov_det: mean_over(steps, StepRecord::cov_det),
            // 100 per measured step, so the sum is exactly 100 x the count, as before.
            fov_percent: mean_over(steps, |s| {
                if s.measurement_enu.is_some() {
                    100.0
                } else {
                    0.0
                }
            }),
            filter_step_ms: median(filter_ms),
            guidance_step_ms: median(guidance_ms),
            first_sighting_s: first.map(|k| steps[k].t_s),
            tracking_error_after_first_sighting_m: first
                .map(|k| mean_over(&steps[k..], StepRecord::tracking_error_m)),
        }
    }
}

/// A number that JSON may hold as `null` (NaN has no JSON form).
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// The mean of `f` over `steps` (0 for none).
fn mean_over(steps: &[StepRecord], f: fn(&StepRecord) -> f64) -> f64 {
    steps.iter().map(f).sum::<f64>() / steps.len().max(1) as f64
}

/// The search apart from the tracking, over a set of runs: how many never saw the target,
/// how long the others searched, and how well they tracked once they had seen it. A run
/// lost for good before its first sighting and one that tracks badly after it have the
/// same mean tracking error; these tell them apart.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct SearchSummary {
    /// Runs in which the target was never measured.
    pub never_seen_runs: usize,
    /// Median time of the first sighting over the runs that had one, s (NaN, written as
    /// null, when none had).
    pub first_sighting_s_median: f64,
    /// Mean and sd over the runs that saw the target of their mean tracking error from the
    /// first sighting on, m.
    pub tracking_error_after_first_sighting_m: MeanSd,
}

impl SearchSummary {
    /// Over these runs' summaries.
    pub fn over(runs: &[RunSummary]) -> Self {
        let firsts: Vec<f64> = runs.iter().filter_map(|r| r.first_sighting_s).collect();
        let after: Vec<f64> = runs
            .iter()
            .filter_map(|r| r.tracking_error_after_first_sighting_m)
            .collect();
        Self {
            never_seen_runs: runs.len() - firsts.len(),
            first_sighting_s_median: median(&firsts),
            tracking_error_after_first_sighting_m: mean_sd(&after),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(agent: Enu2, target: Enu2, est: Enu2, measured: bool) -> StepRecord {
        StepRecord {
            t_s: 0.0,
            target_enu: target,
            agent_enu: agent,
            waypoint_enu: agent,
            measurement_enu: measured.then_some(target),
            estimate_enu: est,
            cov_m2: Matrix2::new(0.02, 0.0, 0.0, 0.5),
            n_eff: 1.0,
            eer: 0.0,
            target_occluded: false,
            target_in_footprint: measured,
        }
    }

    #[test]
    fn summary_averages_the_four_metrics() {
        let steps = vec![
            rec(
                Enu2::new(3.0, 4.0),
                Enu2::zeros(),
                Enu2::new(1.0, 0.0),
                true,
            ),
            rec(Enu2::zeros(), Enu2::zeros(), Enu2::new(0.0, 3.0), false),
        ];
        let s = RunSummary::from_steps(&steps, &[1.0, 3.0, 2.0], &[]);
        assert!((s.tracking_error_m - 2.5).abs() < 1e-12);
        assert!((s.estimation_error_m - 2.0).abs() < 1e-12);
        assert!((s.cov_det - 0.01).abs() < 1e-12);
        assert!((s.fov_percent - 50.0).abs() < 1e-12);
        assert_eq!(s.filter_step_ms, 2.0);
        assert!(s.guidance_step_ms.is_nan());
    }

    #[test]
    fn the_search_ends_at_the_first_measurement_and_tracking_is_averaged_from_there() {
        let at = |t_s: f64, off_m: f64, measured: bool| StepRecord {
            t_s,
            ..rec(
                Enu2::new(off_m, 0.0),
                Enu2::zeros(),
                Enu2::zeros(),
                measured,
            )
        };
        // 100 m off while searching, then 2 m and 4 m off (one step unseen).
        let steps = vec![
            at(0.5, 100.0, false),
            at(1.0, 100.0, false),
            at(1.5, 2.0, true),
            at(2.0, 4.0, false),
        ];
        let s = RunSummary::from_steps(&steps, &[], &[]);
        assert_eq!(s.first_sighting_s, Some(1.5));
        assert!((s.tracking_error_after_first_sighting_m.unwrap() - 3.0).abs() < 1e-12);
        assert!((s.tracking_error_m - 51.5).abs() < 1e-12);
        // Never seen: no search length, no tracking after it.
        let never = RunSummary::from_steps(&steps[..2], &[], &[]);
        assert_eq!(never.first_sighting_s, None);
        assert_eq!(never.tracking_error_after_first_sighting_m, None);
        assert_eq!(RunSummary::from_steps(&[], &[], &[]).first_sighting_s, None);

        let runs = [s, never, s];
        let search = SearchSummary::over(&runs);
        assert_eq!(search.never_seen_runs, 1);
        assert_eq!(search.first_sighting_s_median, 1.5);
        assert!((search.tracking_error_after_first_sighting_m.mean - 3.0).abs() < 1e-12);
        let none = SearchSummary::over(&[never]);
        assert_eq!(none.never_seen_runs, 1);
        assert!(none.first_sighting_s_median.is_nan());
    }
}
