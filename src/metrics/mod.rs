//! The paper's four metrics, per step and per run, and the statistics that compare methods.

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

/// One run's metrics: means over its steps, and timing medians.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct RunSummary {
    /// Mean tracking error, m.
    pub tracking_error_m: f64,
    /// Mean estimation error, m.
    pub estimation_error_m: f64,
    /// Mean det of the covariance, m^4.
    pub cov_det: f64,
    /// Share of steps with a measurement, percent.
    pub fov_percent: f64,
    /// Median filter step time, ms.
    pub filter_step_ms: f64,
    /// Median guidance step time, ms.
    pub guidance_step_ms: f64,
}

impl RunSummary {
    /// From a run's step records and timings.
    pub fn from_steps(steps: &[StepRecord], filter_ms: &[f64], guidance_ms: &[f64]) -> Self {
        let n = steps.len().max(1) as f64;
        Self {
            tracking_error_m: steps.iter().map(|s| s.tracking_error_m()).sum::<f64>() / n,
            estimation_error_m: steps.iter().map(|s| s.estimation_error_m()).sum::<f64>() / n,
            cov_det: steps.iter().map(|s| s.cov_det()).sum::<f64>() / n,
            fov_percent: 100.0
                * steps.iter().filter(|s| s.measurement_enu.is_some()).count() as f64
                / n,
            filter_step_ms: median(filter_ms),
            guidance_step_ms: median(guidance_ms),
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
}
