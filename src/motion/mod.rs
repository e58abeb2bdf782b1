//! Motion models the particle filter predicts with.
//!
//! A model maps each particle's history of its last `K_in` positions (oldest first, world
//! ENU) to its next position, one filter period later. Models take the whole batch in one
//! call so that a learned model can run every particle in one inference. Models are
//! deterministic; the filter adds the process noise.

pub mod constant_velocity;
pub mod dmmn;
pub mod histories;

use thiserror::Error;

pub use constant_velocity::ConstantVelocity;
pub use histories::Histories;

use crate::config::Config;
use crate::world::geometry::Enu2;

/// Names of the motion models a particle filter can use (`--motion`).
pub const MODEL_NAMES: &[&str] = &["cv", "dmmn"];

/// Builds the named motion model for a configuration.
pub fn build(name: &str, cfg: &Config) -> Result<Box<dyn MotionModel>, MotionError> {
    match name {
        "cv" => Ok(Box::new(ConstantVelocity::new(
            cfg.motion.cv_max_speed_mps,
            cfg.filter_dt_s(),
        ))),
        "dmmn" => Ok(Box::new(dmmn::Dmmn::load(&cfg.motion.dmmn_model, cfg)?)),
        other => Err(MotionError::Backend {
            model: other.to_string(),
            message: format!(
                "no such motion model (expected one of {})",
                MODEL_NAMES.join(", ")
            ),
        }),
    }
}

/// Why a motion model could not predict.
#[derive(Debug, Error)]
pub enum MotionError {
    /// The model needs a different history length than the filter keeps.
    #[error(
        "motion model `{model}` needs histories of {expected} positions, the filter keeps {got}"
    )]
    HistoryLength {
        /// The model.
        model: String,
        /// What it needs.
        expected: usize,
        /// What it was given.
        got: usize,
    },
    /// The model's runtime failed.
    #[error("motion model `{model}` failed: {message}")]
    Backend {
        /// The model.
        model: String,
        /// What went wrong.
        message: String,
    },
}

/// A batch predictor of next positions.
pub trait MotionModel: Send {
    /// Short name used in reports (`cv`, `dmmn`).
    fn name(&self) -> &str;

    /// Number of history positions the model reads (`K_in`); `None` if any length works.
    fn required_history_len(&self) -> Option<usize>;

    /// Writes into `out[i]` the predicted next position of track `i` of `histories`.
    ///
    /// `out.len() == histories.len()`. Outputs may be non-finite if the model misbehaves:
    /// the caller checks.
    fn predict(&mut self, histories: &Histories, out: &mut [Enu2]) -> Result<(), MotionError>;
}
