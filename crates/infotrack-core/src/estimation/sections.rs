//! The estimators' tables of a configuration: the particle filter and the Kalman filter.

use serde::{Deserialize, Serialize};

use crate::check::{count, covariance, in_unit, invalid, non_negative, positive, Checked};

/// The particle filter.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterConfig {
    /// Number of particles N.
    pub particles: usize,
    /// Positions of history each particle carries (K_in of the learned model).
    pub history_len: usize,
    /// Process noise Q (2x2), square metres; the filter adds N(0, 2Q) after each prediction
    /// as the paper's code does.
    pub process_noise_cov_m2: [[f64; 2]; 2],
    /// Resampling threshold a: resample when N_eff < a N.
    pub resample_threshold: f64,
    /// Re-seeding threshold b: re-seed around the recent measurements when
    /// N_eff < b N and a measurement arrived.
    pub reseed_threshold: f64,
    /// Roughening constant: jitter sigma = constant x per-axis spread x N^(-1/3).
    pub roughening: f64,
    /// Likelihood of not detecting a target that is in view (negative information).
    pub miss_probability: f64,
    /// Re-draw every particle uniformly when more than this share leaves the workspace.
    pub max_outside_fraction: f64,
    /// How far from a road the target can be, metres (one sigma of the road constraint on
    /// the particles); default: three times the measurement noise's largest sigma. 0 turns
    /// the constraint off. With a motion model that does not know the roads (constant
    /// velocity), a track that clearly heads somewhere is measured to the nearest road it
    /// may drive that way, at most two sigmas more than to the nearest road (a track
    /// driving a one-way road the wrong way fades).
    #[serde(default)]
    pub road_sigma_m: Option<f64>,
    /// Share of the particles replaced, at each step without a measurement before the
    /// first detection, by hypotheses on the roads around the belief, for a motion model
    /// that does not know the roads (constant velocity; once the target has been seen its
    /// particles at a junction are re-routed onto the roads instead); 0 turns both off.
    #[serde(default = "default_hypothesis_injection")]
    pub hypothesis_injection: f64,
}

/// The constant-velocity Kalman filter, state `[x, y, vx, vy]` in the world ENU frame.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KalmanConfig {
    /// Diagonal of the process noise Q: m^2, m^2, (m/s)^2, (m/s)^2.
    pub process_noise_diag: [f64; 4],
    /// Diagonal of the initial covariance P0 (same units).
    pub initial_cov_diag: [f64; 4],
}

fn default_hypothesis_injection() -> f64 {
    0.02
}

impl FilterConfig {
    /// Checks the road terms of `filter` (`hypothesis_injection`, `road_sigma_m`).
    pub fn check_road_terms(&self) -> Checked {
        in_unit("filter.hypothesis_injection", self.hypothesis_injection)?;
        match self.road_sigma_m {
            Some(s) => non_negative("filter.road_sigma_m", s),
            None => Ok(()),
        }
    }

    /// Checks the rest of `filter`: counts, the noise, the thresholds and shares.
    pub fn check(&self) -> Checked {
        count("filter.particles", self.particles)?;
        count("filter.history_len", self.history_len)?;
        if self.history_len < 2 {
            return Err(invalid(
                "filter.history_len",
                self.history_len,
                "must be at least 2 (a velocity needs two positions)",
            ));
        }
        covariance("filter.process_noise_cov_m2", &self.process_noise_cov_m2)?;
        in_unit("filter.resample_threshold", self.resample_threshold)?;
        in_unit("filter.reseed_threshold", self.reseed_threshold)?;
        if self.reseed_threshold > self.resample_threshold {
            return Err(invalid(
                "filter.reseed_threshold",
                self.reseed_threshold,
                "must not exceed filter.resample_threshold",
            ));
        }
        non_negative("filter.roughening", self.roughening)?;
        if !(self.miss_probability > 0.0 && self.miss_probability <= 1.0) {
            return Err(invalid(
                "filter.miss_probability",
                self.miss_probability,
                "must lie in (0, 1]",
            ));
        }
        in_unit("filter.max_outside_fraction", self.max_outside_fraction)
    }
}

impl KalmanConfig {
    /// Checks `kalman`: every variance positive.
    pub fn check(&self) -> Checked {
        for (i, v) in self.process_noise_diag.iter().enumerate() {
            positive(&format!("kalman.process_noise_diag[{i}]"), *v)?;
        }
        for (i, v) in self.initial_cov_diag.iter().enumerate() {
            positive(&format!("kalman.initial_cov_diag[{i}]"), *v)?;
        }
        Ok(())
    }
}
