//! What estimates the target: a particle filter with a motion model, or the
//! constant-velocity Kalman filter (a baseline).

use nalgebra::Matrix2;

use crate::estimation::{FilterError, KalmanFilter, ParticleFilter};
use crate::frames::Enu2;
use crate::motion::{self, MotionModel};
use crate::world::camera::View;
use crate::world::World;

/// Which estimator, by its `--motion` name.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum EstimatorKind {
    /// Particle filter predicting with the named motion model (`cv`, ...).
    Particle(String),
    /// The constant-velocity Kalman filter (`--motion kf`).
    Kalman,
}

/// A `--motion` name that names no estimator.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown motion model `{name}` (expected one of kf, {})", motion::MODEL_NAMES.join(", "))]
pub struct UnknownEstimator {
    /// What was asked for.
    pub name: String,
}

impl EstimatorKind {
    /// From a `--motion` name.
    pub fn parse(name: &str) -> Result<Self, UnknownEstimator> {
        let name = name.trim();
        if name == "kf" {
            Ok(Self::Kalman)
        } else if motion::MODEL_NAMES.contains(&name) {
            Ok(Self::Particle(name.to_string()))
        } else {
            Err(UnknownEstimator {
                name: name.to_string(),
            })
        }
    }

    /// The `--motion` name.
    pub fn name(&self) -> &str {
        match self {
            Self::Particle(m) => m,
            Self::Kalman => "kf",
        }
    }
}

/// What a tracker estimates with, ready: a particle filter's motion model (built by the
/// caller, which may read a learned model's file), or the Kalman filter.
pub enum EstimatorModel {
    /// A particle filter predicting with `model`.
    Particle {
        /// The model's `--motion` name (for messages).
        name: String,
        /// The model.
        model: Box<dyn MotionModel>,
    },
    /// The constant-velocity Kalman filter.
    Kalman,
}

impl EstimatorModel {
    /// The `--motion` name.
    pub fn name(&self) -> &str {
        match self {
            Self::Particle { name, .. } => name,
            Self::Kalman => "kf",
        }
    }
}

impl EstimatorKind {
    /// Builds the named estimator's model; a learned one through `learned` (the DMMN reads
    /// its ONNX file and metadata).
    pub fn build(
        &self,
        params: &motion::MotionParams,
        learned: motion::LearnedLoader<'_>,
    ) -> Result<EstimatorModel, motion::MotionError> {
        Ok(match self {
            Self::Particle(name) => EstimatorModel::Particle {
                name: name.clone(),
                model: motion::build(name, params, learned)?,
            },
            Self::Kalman => EstimatorModel::Kalman,
        })
    }
}

/// A built estimator.
pub enum Estimator {
    /// Particle filter and the model it predicts with.
    Particle {
        /// The filter.
        pf: Box<ParticleFilter>,
        /// Its motion model.
        model: Box<dyn MotionModel>,
    },
    /// Kalman filter.
    Kalman(Box<KalmanFilter>),
}

impl Estimator {
    /// The estimate, world ENU.
    pub fn mean(&self) -> Enu2 {
        match self {
            Self::Particle { pf, .. } => pf.mean(),
            Self::Kalman(kf) => kf.mean(),
        }
    }

    /// Its covariance, m^2.
    pub fn covariance(&self) -> Matrix2<f64> {
        match self {
            Self::Particle { pf, .. } => pf.covariance(),
            Self::Kalman(kf) => kf.covariance(),
        }
    }

    /// The largest standard deviation of the estimate, m.
    pub fn largest_sd_m(&self) -> f64 {
        self.covariance()
            .symmetric_eigenvalues()
            .max()
            .max(0.0)
            .sqrt()
    }

    /// The estimate's velocity, world ENU, m/s.
    pub fn velocity(&self) -> Enu2 {
        match self {
            Self::Particle { pf, .. } => pf.mean_velocity(),
            Self::Kalman(kf) => kf.velocity(),
        }
    }

    /// The particle filter, if this is one.
    pub fn particle_filter(&self) -> Option<&ParticleFilter> {
        match self {
            Self::Particle { pf, .. } => Some(pf),
            Self::Kalman(_) => None,
        }
    }

    /// One filter step with what the camera saw from `view` (`z`: the target's
    /// measured position, or `None` for a frame without it). Returns N_eff (NaN for the
    /// Kalman filter).
    pub fn step<R: rand::Rng + ?Sized>(
        &mut self,
        z: Option<Enu2>,
        view: &View,
        world: &World,
        rng: &mut R,
    ) -> Result<f64, FilterError> {
        match self {
            Self::Particle { pf, model } => Ok(pf.step(model.as_mut(), z, view, world, rng)?.n_eff),
            Self::Kalman(kf) => {
                kf.step(z);
                Ok(f64::NAN)
            }
        }
    }

    /// One step without a frame: predict only, no negative information.
    pub fn step_blind<R: rand::Rng + ?Sized>(&mut self, rng: &mut R) -> Result<f64, FilterError> {
        match self {
            Self::Particle { pf, model } => Ok(pf.step_blind(model.as_mut(), rng)?.n_eff),
            Self::Kalman(kf) => {
                kf.step(None);
                Ok(f64::NAN)
            }
        }
    }
}
